// SPDX-License-Identifier: BSD-3-Clause
// Scene file parsing: one TomlReader per section, defaults from the libraries' Default…().
#include <spheretouch/engine/scene.hpp>
#include <spheretouch/geom/text_file.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <fstream>
#include <sstream>
#include <unistd.h>

#include <spheretouch/config/toml_reader.hpp>
#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/net/curve_keys.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

using config::TomlReader;

namespace {

constexpr double kMs = 1e6;  // ns per ms

/// Empty when `path` exists, else why not. Only asks (a stat): parsing loads no file. A path the
/// system refuses to look up (a name too long, no permission) is an error here, never an exception.
std::string lookup(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) return {};
  if (ec) return "cannot look up " + path + ": " + ec.message();
  return "file " + path + " does not exist";
}

/// A material's fields, in [force] (the default material) and in [object.material]: the force
/// law and its constants, the damping, the friction. Fields not given keep what `m` holds.
void read_material(TomlReader& r, Material& m) {
  std::string law = m.law.kind == rt::LawKind::log ? "log" : "linear";
  r.string("law", law, {"log", "linear"});
  m.law.kind = law == "log" ? rt::LawKind::log : rt::LawKind::linear;
  r.number("a", m.law.a, -1e6, 1e6);
  r.number("b_n", m.law.b_N, 1e-9, 1e6);
  r.number("log_base", m.law.log_base, 1.000001, 1e6);
  r.number("pd_unit_mm", m.law.pd_unit_mm, 1e-9, 1e9);
  r.number("spring_n_per_mm", m.law.spring_N_per_mm, 1e-9, 1e6);
  r.number("damping_n_s_per_mm", m.damping_N_s_per_mm, 0, 1e3);
  r.number("static_friction", m.friction.static_mu, 0, 10);
  r.number("dynamic_friction", m.friction.dynamic_mu, 0, 10);
  r.number("friction_stiffness_n_per_mm", m.friction.stiffness_N_per_mm, 0, 1e6);
  if (m.friction.dynamic_mu > m.friction.static_mu)
    r.error(
        r.has("dynamic_friction") ? "dynamic_friction" : "static_friction",
        "dynamic_friction must not exceed static_friction (a contact that slides harder than it sticks never sticks)");
}

/// The scene's default material ([force]) as its fields hold it.
Material scene_material(const Scene& s) { return Material{s.law, s.interp.damping_N_s_per_mm, s.friction}; }

/// Sets the scene's material fields (the single object's, or the first of several).
void set_material(Scene& s, const Material& m) {
  s.law = m.law;
  s.interp.damping_N_s_per_mm = m.damping_N_s_per_mm;
  s.friction = m.friction;
}

/// An object's name, placement and material table (the body is read by read_body).
const toml::table* read_object_extras(TomlReader& r, ObjectSpec& o, bool& placed) {
  r.string("name", o.name);
  std::vector<double> pos, rot;
  r.numbers("position_mm", pos, 3);
  r.numbers("rotation_deg", rot, 3);
  placed = !pos.empty() || !rot.empty() || !o.name.empty();
  if (!pos.empty()) o.placement.position_mm = geom::Vec3(pos[0], pos[1], pos[2]);
  if (!rot.empty()) o.placement.rotation_deg = geom::Vec3(rot[0], rot[1], rot[2]);
  if (!pos.empty() && o.placement.position_mm.cwiseAbs().maxCoeff() > 1e9)
    r.error("position_mm", "expected coordinates within 1e9 mm");
  return r.table("material");
}

void read_body(TomlReader& r, BodySpec& b, const std::string& dir, const std::string& field) {
  std::string mesh;
  r.string("mesh", mesh);
  r.string("builtin", b.builtin, {"icosphere", "box", "capsule"});
  r.number("radius_mm", b.radius_mm, 1e-6, 1e9);
  r.number("length_mm", b.length_mm, 0, 1e9);
  r.number("size_mm", b.size_mm, 1e-6, 1e9);
  r.integer("frequency", b.frequency, 1, 200);
  r.integer("segments", b.segments, 3, 1000);
  r.string("units", b.units, {"um", "mm", "cm", "m", "in"});
  r.number("scale", b.scale, 1e-12, 1e12);
  r.boolean("orient", b.orient);
  if (!mesh.empty() && !b.builtin.empty()) r.error("mesh", "give either mesh or builtin, not both");
  if (mesh.empty() && b.builtin.empty()) r.error("mesh", "expected a mesh path (or \"model:NAME\") or a builtin shape");
  if (mesh.rfind("model:", 0) == 0)
    b.mesh = model_dir() + "/" + mesh.substr(6);
  else if (!mesh.empty())
    b.mesh = std::filesystem::path(mesh).is_absolute() ? mesh : dir + "/" + mesh;
  if (!b.mesh.empty())
    if (std::string why = lookup(b.mesh); !why.empty())
      r.error("mesh", why + (mesh.rfind("model:", 0) == 0 ? " (run scripts/models.sh to build the model set)" : ""));
  (void)field;
}

geom::Vec3 vec3(const std::vector<double>& v) { return geom::Vec3(v[0], v[1], v[2]); }

}  // namespace

std::string model_dir() {
  if (const char* d = std::getenv("ST_MODEL_DIR"); d && *d) return d;
  // The executable lives in <source>/build*/: look for <source>/.cache/models beside it.
  char buf[4096];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n > 0) {
    std::filesystem::path p(std::string(buf, std::size_t(n)));
    for (int up = 0; up < 3 && p.has_parent_path(); ++up) {
      p = p.parent_path();
      std::error_code ec;
      if (std::filesystem::exists(p / ".cache" / "models", ec)) return (p / ".cache" / "models").string();
    }
  }
  return ".cache/models";
}

Scene DefaultScene() {
  Scene s;
  s.probe.builtin = "capsule";
  s.probe.radius_mm = 8;
  s.probe.length_mm = 40;
  s.object.builtin = "icosphere";
  s.object.radius_mm = 50;
  s.object.frequency = 40;
  return s;
}

Result<Scene> parse_scene(const std::string& text, const std::string& name, const std::string& dir) {
  Result<toml::table> parsed = config::parse_toml(text, name);
  if (!parsed) return Error{parsed.error()};
  const toml::table& root = parsed.value();
  Scene s = DefaultScene();
  s.file = name;
  TomlReader top(&root, "", name);
  for (const char* sec : {"probe", "object", "tree", "workers", "collision", "haptic", "force", "interpolation",
                          "contact", "passivity", "device", "output", "run"})
    top.known(sec);
  if (Status st = top.finish(); !st) return Error{st.error()};
  for (const char* sec : {"probe", "object"})
    if (!root.contains(sec))
      return fail(name, ": missing section [", sec, "] (every scene names its probe and object)");

  auto section = [&](const char* key) { return root.get_as<toml::table>(key); };
  auto check_table = [&](const char* key) -> Status {
    if (root.contains(key) && !root.get_as<toml::table>(key))
      return fail(name, ": ", key, ": expected a [", key, "] table");
    return Ok{};
  };
  for (const char* sec : {"probe", "tree", "workers", "collision", "haptic", "force", "interpolation", "contact",
                          "passivity", "device", "output", "run"})
    if (Status st = check_table(sec); !st) return Error{st.error()};
  if (root.contains("object") && !root.get_as<toml::table>("object") && !root.get_as<toml::array>("object"))
    return fail(name, ": object: expected an [object] table or [[object]] tables");

  {
    s.probe = {};
    TomlReader r(section("probe"), "probe", name);
    read_body(r, s.probe, dir, "probe");
    std::vector<double> tip, rot;
    r.numbers("tip", tip, 3);
    r.numbers("rotation_deg", rot, 3);
    if (!tip.empty()) {
      s.probe_tip_auto = false;
      s.probe_tip = vec3(tip);
    }
    if (!rot.empty()) s.probe_rotation_deg = vec3(rot);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  // [object] (one object) or [[object]] (several): bodies and placements now, materials after
  // [force] (their default).
  std::vector<const toml::table*> object_materials;
  bool several = false;
  if (const toml::array* arr = root.get_as<toml::array>("object")) {
    several = true;
    if (arr->empty()) return fail(name, ": object: expected at least one [[object]] table");
    if (arr->size() > kMaxSceneObjects)
      return fail(name, ": object: ", arr->size(), " objects, at most ", kMaxSceneObjects, " are supported");
    for (std::size_t i = 0; i < arr->size(); ++i) {
      const std::string path = "object[" + std::to_string(i + 1) + "]";
      const toml::table* t = (*arr)[i].as_table();
      if (!t) return fail(name, ": ", path, ": expected a table ([[object]])");
      ObjectSpec o;
      TomlReader r(t, path, name);
      read_body(r, o.body, dir, path);
      bool placed = false;
      object_materials.push_back(read_object_extras(r, o, placed));
      if (o.name.empty()) o.name = "object " + std::to_string(i + 1);
      for (const ObjectSpec& other : s.objects)
        if (other.name == o.name) r.error("name", "'" + o.name + "' names an earlier object too (names are unique)");
      if (Status st = r.finish(); !st) return Error{st.error()};
      s.objects.push_back(std::move(o));
    }
    s.object = s.objects.front().body;
  } else {
    s.object = {};
    TomlReader r(section("object"), "object", name);
    read_body(r, s.object, dir, "object");
    ObjectSpec o;
    bool placed = false;
    object_materials.push_back(read_object_extras(r, o, placed));
    if (Status st = r.finish(); !st) return Error{st.error()};
    if (placed) {  // a placed single object is a world of one
      several = true;
      o.body = s.object;
      if (o.name.empty()) o.name = "object 1";
      s.objects.push_back(std::move(o));
    }
  }
  {
    TomlReader r(section("tree"), "tree", name);
    r.integer("leaf_faces", s.tree.leaf_faces, 1, geom::kMaxLeafFaces);
    r.integer_or_auto("layer", s.layer, 0, 20, geom::kFree);
    r.integer_or_auto("block_size", s.block_size, 1, 1 << 20, 0u);
    std::string mapping = geom::to_string(s.mapping);
    r.string("mapping", mapping, {"block-cyclic", "contiguous", "random"});
    geom::parse_mapping(mapping, s.mapping);
    r.boolean("cache", s.tree_cache);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("workers"), "workers", name);
    r.integer("count", s.workers, 0, 64);
    r.strings("endpoints", s.endpoints);
    r.number("deadline_ms", s.deadline_ms, 0.1, 10000);
    r.integer("down_after", s.down_after, 1, 1000);
    r.integer_or_auto("assist_blocks", s.assist_blocks, 0, 256, -1);
    r.boolean("replicas", s.replicas);
    for (const std::string& ep : s.endpoints)
      if (ep.rfind("tcp://", 0) != 0 && ep.rfind("ipc://", 0) != 0)
        r.error("endpoints", "expected tcp://HOST:PORT or ipc://PATH endpoints (found '" + ep + "')");
    // CURVE keys: paths relative to the scene; read (and the secret's mode checked) when the run
    // connects, so the servo process that re-reads the scene never touches them.
    auto resolve = [&](const std::string& p) {
      return p.empty() || std::filesystem::path(p).is_absolute() ? p : dir + "/" + p;
    };
    r.string("server_key", s.server_key);
    r.string("client_key", s.client_key);
    s.server_key = resolve(s.server_key);
    s.client_key = resolve(s.client_key);
    if (!s.server_key.empty() && s.client_key.empty())
      r.error("client_key", "server_key is set but client_key is not: CURVE needs this client's key pair too");
    else if (s.server_key.empty() && !s.client_key.empty())
      r.error("server_key", "client_key is set but server_key is not: CURVE needs the workers' public key too");
    if (!s.server_key.empty() && !std::filesystem::exists(s.server_key))
      r.error("server_key",
              "file " + s.server_key + " does not exist (the workers' PREFIX.pub from `spheretouch keygen`)");
    if (!s.client_key.empty() && !std::filesystem::exists(net::key_files(s.client_key).secret_file))
      r.error("client_key", "file " + net::key_files(s.client_key).secret_file +
                                " does not exist (make the pair with `spheretouch keygen --out PREFIX`)");
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("collision"), "collision", name);
    r.number("rate_hz", s.collision_rate_hz, 0, 100000);
    std::string mode = "exact";
    r.string("mode", mode, {"exact", "approximate"});
    int layer = geom::kLeafSpheres;
    r.integer("approx_layer", layer, -1, 64);
    if (mode == "approximate")
      s.approx_layer = layer;
    else if (r.has("approx_layer"))
      r.error("approx_layer", "only meaningful with mode = \"approximate\"");
    r.boolean("coherent", s.coherent);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("haptic"), "haptic", name);
    r.number("rate_hz", s.haptic.rate_hz, rt::kMinRateHz, rt::kMaxRateHz);
    r.integer("fifo_priority", s.haptic.fifo_priority, 0, 99);
    r.integer("cpu", s.haptic.cpu, -1, 4095);
    r.boolean("lock_memory", s.haptic.lock_memory);
    std::size_t prefault_kb = s.haptic.prefault_stack_bytes / 1024;
    r.integer("prefault_stack_kb", prefault_kb, 0, 65536);
    s.haptic.prefault_stack_bytes = prefault_kb * 1024;
    std::size_t stack_kb = s.thread_stack_bytes / 1024;
    r.integer("thread_stack_kb", stack_kb, 0, 1 << 20);
    if (stack_kb != 0 && stack_kb < 64) r.error("thread_stack_kb", "expected 0 (glibc's default) or at least 64");
    s.thread_stack_bytes = stack_kb * 1024;
    const std::size_t margin_kb = rt::kPrefaultStackMargin / 1024;
    if (stack_kb != 0 && prefault_kb > 0 && prefault_kb + margin_kb > stack_kb)
      r.error("prefault_stack_kb",
              std::to_string(prefault_kb) + " KiB does not fit the haptic thread's stack (thread_stack_kb = " +
                  std::to_string(stack_kb) + ", of which " + std::to_string(margin_kb) + " KiB stay free)");
    r.boolean("strict", s.haptic.strict);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("force"), "force", name);
    Material m = scene_material(s);
    read_material(r, m);
    set_material(s, m);
    r.number("peak_n", s.saturation.peak_N, 1e-9, 1e4);
    s.law.max_force_N = s.saturation.peak_N;
    r.boolean("sustained_limit", s.saturation.sustained);
    r.number("continuous_n", s.saturation.continuous_N, 1e-9, 1e4);
    r.number("sustained_tau_s", s.saturation.tau_s, 1e-3, 1e5);
    if (s.saturation.continuous_N > s.saturation.peak_N) r.error("continuous_n", "must not exceed peak_n");
    if (Status st = r.finish(); !st) return Error{st.error()};
    if (Result<rt::ForceLaw> l = rt::ForceLaw::make(s.law); !l) return fail(name, ": [force] ", l.error());
    if (std::string e = rt::Saturator::check(s.saturation); !e.empty()) return fail(name, ": [force] ", e);
  }
  {
    // Each object's material: [force]'s material fields (the default) overridden where it says.
    const Material def = scene_material(s);
    for (std::size_t i = 0; i < object_materials.size(); ++i) {
      Material m = def;
      const std::string path = several && root.get_as<toml::array>("object")
                                   ? "object[" + std::to_string(i + 1) + "].material"
                                   : std::string("object.material");
      if (object_materials[i]) {
        TomlReader r(object_materials[i], path, name);
        read_material(r, m);
        if (Status st = r.finish(); !st) return Error{st.error()};
        if (Result<rt::ForceLaw> l = rt::ForceLaw::make(m.law); !l) return fail(name, ": [", path, "] ", l.error());
      }
      if (several)
        s.objects[i].material = m;
      else
        set_material(s, m);
    }
    if (several) set_material(s, s.objects.front().material);  // the first object's, for code that knows one
  }
  {
    TomlReader r(section("interpolation"), "interpolation", name);
    std::string method = "plane";
    r.string("method", method, {"hold", "paper", "plane"});
    s.interp.mode = rt::parse_interp_mode(method).value();
    double crossfade_ms = double(s.interp.crossfade_ns) / kMs, timeout_ms = double(s.interp.stale_timeout_ns) / kMs,
           fade_ms = double(s.interp.fade_ns) / kMs;
    r.number("crossfade_ms", crossfade_ms, 0, 10000);
    r.number("timeout_ms", timeout_ms, 1, 100000);
    r.number("fade_ms", fade_ms, 0, 100000);
    r.number("paper_gain_n_per_mm", s.interp.paper_gain_N_per_mm, 0, 1e3);
    r.number("paper_max_move_mm", s.interp.paper_max_move_mm, 0, 1e3);
    s.interp.crossfade_ns = std::int64_t(crossfade_ms * kMs);
    s.interp.stale_timeout_ns = std::int64_t(timeout_ms * kMs);
    s.interp.fade_ns = std::int64_t(fade_ms * kMs);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("contact"), "contact", name);
    std::string model = geom::to_string(s.contact.model);
    r.string("model", model, {"patch", "paper"});
    s.contact.model = geom::parse_contact_model(model).value();
    r.number("hold_margin_mm", s.contact.hold_margin_mm, 0, 1e4);
    r.number("replane_angle_deg", s.contact.replane_angle_deg, 0, 180);
    r.integer("max_inside_vertices", s.contact.max_inside_vertices, 1, 1 << 26);
    if (Status st = r.finish(); !st) return Error{st.error()};
    if (std::string e = geom::check(s.contact); !e.empty()) return fail(name, ": [contact] ", e);
  }
  {
    TomlReader r(section("passivity"), "passivity", name);
    r.boolean("enabled", s.passivity.enabled);
    r.number("colgate_margin", s.passivity.colgate_margin, 0, 100);
    r.number("max_damping_n_s_per_mm", s.passivity.max_damping_N_s_per_mm, 0, 10);
    if (Status st = r.finish(); !st) return Error{st.error()};
    if (std::string e = rt::PassivityGuard::check(s.passivity); !e.empty()) return fail(name, ": [passivity] ", e);
  }
  {
    TomlReader r(section("device"), "device", name);
    r.string("kind", s.device.kind, {"simulated", "udp", "browser"});
    rt::UdpDeviceConfig& u = s.device.udp;
    r.string("bind", u.bind);
    r.string("peer", u.peer);
    r.number("silence_ms", u.silence_ms, 1, 10000);
    r.number("fade_ms", u.fade_ms, 1, 10000);
    r.number("scale", u.scale, 1e-6, 1e6);
    std::vector<double> offset;
    r.numbers("offset_mm", offset, 3);
    if (!offset.empty()) u.offset_mm = {offset[0], offset[1], offset[2]};
    std::string auth = u.auth == rt::BridgeAuth::kHmac ? "hmac" : "none";
    r.string("auth", auth, {"hmac", "none"});
    u.auth = auth == "hmac" ? rt::BridgeAuth::kHmac : rt::BridgeAuth::kNone;
    r.string("key_file", s.device.key_file);
    if (!s.device.key_file.empty() && !std::filesystem::path(s.device.key_file).is_absolute())
      s.device.key_file = dir + "/" + s.device.key_file;
    if (!s.device.key_file.empty() && u.auth == rt::BridgeAuth::kNone)
      r.error("key_file", "is set but auth = \"none\": remove one (an unused key would look like protection)");
    else if (!s.device.key_file.empty())
      if (std::string why = lookup(s.device.key_file); !why.empty())
        r.error("key_file", "bridge key " + why + " (spheretouch keygen --bridge --out FILE makes one)");
    r.number("session_timeout_ms", u.session_timeout_ms, 1, 600000);
    r.integer("max_seq_jump", u.max_seq_jump, 1, 1000000000);
    r.number("max_pose_step_mm", u.max_pose_step_mm, 1e-6, 1e6);
    r.number("max_rotation_step_deg", u.max_rotation_step_deg, 1e-6, 180);
    r.number("max_force_step_n", u.max_force_step_N, 1e-6, 1000);
    r.number("max_torque_step_nm", u.max_torque_step_Nm, 1e-9, 100);
    r.string("script", s.device.script);
    if (s.device.script != "builtin" && !std::filesystem::path(s.device.script).is_absolute())
      s.device.script = dir + "/" + s.device.script;
    if (s.device.script != "builtin")
      if (std::string why = lookup(s.device.script); !why.empty())
        r.error("script", "trajectory " + why + " (or use \"builtin\")");
    std::vector<double> target, normal;
    if (root["device"]["target"].is_string()) {
      std::string t;
      r.string("target", t, {"top"});
    } else {
      r.numbers("target", target, 3);
      if (!target.empty()) {
        s.device.target_top = false;
        s.device.target = vec3(target);
      }
    }
    r.numbers("normal", normal, 3);
    if (!normal.empty()) {
      if (vec3(normal).norm() < 1e-9)
        r.error("normal", "must not be the zero vector");
      else
        s.device.normal = vec3(normal).normalized();
    }
    r.number("press_mm", s.device.press_mm, 0, 1000);
    r.number("slide_mm", s.device.slide_mm, 0, 10000);
    r.boolean("virtual_user", s.device.user.enabled);
    r.number("user_stiffness_n_per_mm", s.device.user.stiffness_N_per_mm, 1e-6, 100);
    r.boolean("repeat", s.device.repeat);
    r.integer("dof", s.device.wrench.dof, 3, 6);
    if (s.device.wrench.dof != 3 && s.device.wrench.dof != 6) r.error("dof", "must be 3 or 6");
    r.number("torque_limit_nm", s.device.wrench.torque_limit_Nm, 0, 100);
    std::vector<double> tcp;
    r.numbers("tcp_mm", tcp, 3);
    if (!tcp.empty()) {
      s.device.tcp_auto = false;
      s.device.wrench.tcp_mm = vec3(tcp);
    }
    if (s.device.wrench.dof == 6 && !(s.device.wrench.torque_limit_Nm > 0))
      r.error("torque_limit_nm", "a 6-DOF device (dof = 6) needs a torque limit > 0, N·m");
    if (!(u.session_timeout_ms >= u.silence_ms))
      r.error("session_timeout_ms", "must be >= silence_ms: a session is never replaced while its force is still on");
    else if (s.device.kind == "udp")
      if (std::string why = rt::check(u); !why.empty()) r.error("auth", why);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("output"), "output", name);
    r.string("dir", s.out_dir);
    r.boolean("trace", s.write_trace);
    r.boolean("perfetto", s.write_perfetto);
    r.boolean("ply", s.write_ply);
    r.string("status", s.status, {"auto", "tty", "plain", "off"});
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  {
    TomlReader r(section("run"), "run", name);
    r.number("duration_s", s.duration_s, 0.01, 1e6);
    if (Status st = r.finish(); !st) return Error{st.error()};
  }
  if (std::string e = rt::HapticLoop::check(s.haptic); !e.empty()) return fail(name, ": [haptic] ", e);
  return s;
}

geom::Pose Placement::pose() const {
  const geom::Vec3 r = rotation_deg * (M_PI / 180.0);
  geom::Pose p = geom::Pose::Identity();
  p.translate(position_mm);
  p.rotate(Eigen::AngleAxisd(r.x(), geom::Vec3::UnitX()) * Eigen::AngleAxisd(r.y(), geom::Vec3::UnitY()) *
           Eigen::AngleAxisd(r.z(), geom::Vec3::UnitZ()));
  return p;
}

std::vector<ObjectSpec> scene_objects(const Scene& s) {
  if (!s.objects.empty()) return s.objects;
  ObjectSpec o;
  o.name = "object";
  o.body = s.object;
  o.material = scene_material(s);
  return {o};
}

Status set_servo_materials(rt::HapticServo& servo, const Scene& s) {
  std::vector<rt::ObjectMaterial> materials;
  for (const ObjectSpec& o : scene_objects(s)) {
    Result<rt::ForceLaw> law = rt::ForceLaw::make(o.material.law);
    if (!law) return fail(s.file, ": ", o.name, ": ", law.error());
    materials.push_back({law.value(), o.material.damping_N_s_per_mm, o.material.friction});
  }
  servo.set_objects(materials);
  return Ok{};
}

std::string bridge_key_path(const std::string& run_dir) { return run_dir + "/bridge.key"; }

Result<rt::UdpDeviceConfig> udp_device_config(const Scene& s, const std::string& run_dir, bool make_key) {
  rt::UdpDeviceConfig c = s.device.udp;
  c.max_force_N = s.saturation.peak_N;
  c.max_torque_Nm = s.device.wrench.dof == 6 ? s.device.wrench.torque_limit_Nm : 0.0;
  if (c.auth == rt::BridgeAuth::kNone) return c;
  if (!s.device.key_file.empty()) {
    Result<rt::BridgeKey> k = rt::read_bridge_key(s.device.key_file);
    if (!k) return fail(s.file, ": device.key_file: ", k.error());
    c.key = k.value();
    return c;
  }
  const std::string path = bridge_key_path(run_dir);
  if (make_key) {
    Result<rt::BridgeKey> k = rt::random_bridge_key();
    if (!k) return fail(s.file, ": device.auth: ", k.error());
    if (Status st = rt::write_bridge_key(path, k.value(), true); !st) return Error{st.error()};
    c.key = k.value();
    return c;
  }
  Result<rt::BridgeKey> k = rt::read_bridge_key(path);
  if (!k) return fail(s.file, ": the run's bridge key: ", k.error());
  c.key = k.value();
  return c;
}

Result<Scene> load_scene(const std::string& path) {
  Result<std::string> text = geom::read_text_file(path, kMaxSceneBytes, "scene file");
  if (!text) return Error{text.error()};
  const std::string dir = std::filesystem::path(path).parent_path().string();
  return parse_scene(text.value(), path, dir.empty() ? "." : dir);
}

rt::Trajectory builtin_script(const Scene& s, const geom::Mesh& probe, std::span<const geom::Mesh* const> objects) {
  const geom::Vec3 n = s.device.normal;
  geom::Vec3 target = s.device.target;
  if (s.device.target_top) {  // the extreme vertex along the normal over every object, in the world
    const std::vector<ObjectSpec> specs = scene_objects(s);
    double best = -std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < objects.size(); ++k) {
      const geom::Pose place = k < specs.size() ? specs[k].placement.pose() : geom::Pose::Identity();
      const geom::Mesh& object = *objects[k];
      for (std::uint32_t i = 0; i < object.num_vertices(); ++i) {
        const geom::Vec3 v = place * object.vertex(i);
        if (const double d = v.dot(n); d > best) {
          best = d;
          target = v;
        }
      }
    }
  }
  const geom::Pose grip = probe_grip(s, probe);
  rt::Trajectory t = rt::builtin_press_slide(target, n, s.device.press_mm, s.device.slide_mm);
  for (rt::TimedPose& k : t.keys) {
    geom::Pose p = geom::Pose::Identity();
    p.translate(k.pose.translation());
    k.pose = p * grip;
  }
  return t;
}

rt::Trajectory builtin_script(const Scene& s, const geom::Mesh& probe, const geom::Mesh& object) {
  const geom::Mesh* one[] = {&object};
  return builtin_script(s, probe, one);
}

geom::Pose probe_grip(const Scene& s, const geom::Mesh& probe) {
  const geom::Vec3 n = s.device.normal;
  const geom::Vec3 r = s.probe_rotation_deg * (M_PI / 180.0);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(r.x(), geom::Vec3::UnitX()) *
                             Eigen::AngleAxisd(r.y(), geom::Vec3::UnitY()) * Eigen::AngleAxisd(r.z(), geom::Vec3::UnitZ()))
                                .toRotationMatrix();
  geom::Vec3 tip = s.probe_tip;
  if (s.probe_tip_auto) {  // the probe's lowest vertex along the approach direction
    double best = std::numeric_limits<double>::infinity();
    for (std::uint32_t i = 0; i < probe.num_vertices(); ++i)
      if (const double d = (R * probe.vertex(i)).dot(n); d < best) {
        best = d;
        tip = probe.vertex(i);
      }
  }
  geom::Pose g = geom::Pose::Identity();
  g.rotate(R);
  g.translate(-tip);
  return g;
}

geom::Vec3 tool_point(const Scene& s, const geom::Mesh& probe) {
  return s.device.tcp_auto ? geom::Vec3(probe_grip(s, probe).inverse().translation()) : s.device.wrench.tcp_mm;
}

Result<geom::Mesh> load_body(const BodySpec& b, const std::string& field) {
  if (!b.builtin.empty()) {
    if (b.builtin == "icosphere") return geom::make_icosphere(b.radius_mm, b.frequency);
    if (b.builtin == "box") return geom::make_box(geom::Vec3::Constant(b.size_mm));
    return geom::make_capsule(b.radius_mm, b.length_mm, b.segments);
  }
  geom::LoadConfig o;
  o.units = b.units;
  o.scale = b.scale;
  o.orient = b.orient;
  Result<geom::LoadedMesh> r = geom::load_mesh(b.mesh, o);
  if (!r) return fail("[", field, "] ", r.error());
  if (const std::string w = geom::describe_winding(r.value().report.orientation); !w.empty())
    std::fprintf(stderr, "[%s] %s: %s (set [%s] orient = false to keep the file's)\n", field.c_str(), b.mesh.c_str(),
                 w.c_str(), field.c_str());
  // Loads anyway (a tiny or huge object may be meant), but says so where the run starts.
  if (!r.value().report.size_warning.empty())
    std::fprintf(stderr, "[%s] %s (set [%s] units or scale)\n", field.c_str(), r.value().report.size_warning.c_str(),
                 field.c_str());
  return std::move(r.value().mesh);
}

rt::SceneRef scene_ref(const std::string& scene_path, const geom::Mesh& probe, const geom::Mesh& object) {
  rt::SceneRef r;
  if (scene_path.size() < rt::SceneRef::kMaxPath) std::memcpy(r.scene_path, scene_path.c_str(), scene_path.size() + 1);
  r.probe_hash = geom::mesh_hash(probe);
  r.object_hash = geom::mesh_hash(object);
  r.probe_vertices = std::uint32_t(probe.num_vertices());
  r.probe_faces = std::uint32_t(probe.num_faces());
  r.object_vertices = std::uint32_t(object.num_vertices());
  r.object_faces = std::uint32_t(object.num_faces());
  return r;
}

std::string compare_scene_ref(const rt::SceneRef& ref, const geom::Mesh& probe, const geom::Mesh& object) {
  std::string out;
  auto body = [&out](const char* what, const geom::Mesh& m, std::uint32_t nv, std::uint32_t nf, std::uint64_t hash) {
    if (!out.empty()) return;
    char line[256];
    if (m.num_vertices() != nv || m.num_faces() != nf)
      std::snprintf(line, sizeof line, "the %s has %zu vertices and %zu faces, the run's had %u and %u", what,
                    m.num_vertices(), m.num_faces(), nv, nf);
    else if (geom::mesh_hash(m) != hash)
      std::snprintf(line, sizeof line, "the %s has the run's %zu vertices and %zu faces but other coordinates or faces",
                    what, m.num_vertices(), m.num_faces());
    else
      return;
    out = line;
  };
  body("probe", probe, ref.probe_vertices, ref.probe_faces, ref.probe_hash);
  body("object", object, ref.object_vertices, ref.object_faces, ref.object_hash);
  return out;
}

}  // namespace st::engine
