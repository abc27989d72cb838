// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/engine/scene.hpp>: scene files (configs/*.toml), what `spheretouch run` and
/// RunEngine touch and with which knobs. Every field is checked where it is read, unknown keys
/// are rejected, and only the bodies named are loaded. configs/demo.toml documents every field.
#pragma once
#include <spheretouch/abi.hpp>
#include <span>
#include <string>
#include <vector>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/rt/force_law.hpp>
#include <spheretouch/rt/friction.hpp>
#include <spheretouch/rt/haptic_loop.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/interpolator.hpp>
#include <spheretouch/rt/passivity.hpp>
#include <spheretouch/rt/saturation.hpp>
#include <spheretouch/rt/shm_status.hpp>
#include <spheretouch/rt/simulated_device.hpp>
#include <spheretouch/rt/udp_device.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// [workers] assist_blocks = "auto" with worker daemons: at ~1,000 contacts the client assist
/// takes 5-8 blocks a round (spheretouch-bench scale, perf/RESULTS.md "Scale-out", client assist).
inline constexpr std::uint32_t kAutoAssistBlocks = 8;

/// One body: a mesh file, the model set ("model:NAME") or a generated shape.
struct BodySpec {
  std::string mesh;     ///< resolved file path; empty for a generated body
  std::string builtin;  ///< "icosphere", "box", "capsule" when generated
  ///@{
  double radius_mm = 10, length_mm = 30, size_mm = 40;  ///< generated shape dimensions
  ///@}
  ///@{
  int frequency = 7, segments = 24;  ///< generated shape resolution
  ///@}
  std::string units = "mm";  ///< unit of the file's coordinates
  double scale = 1;          ///< extra factor
  bool orient = true;        ///< make the faces' winding consistent and outward (geom::LoadConfig::orient)
};

/// Where an object sits in the world: its file coordinates are turned by rotation_deg (XYZ Euler,
/// degrees, about the file's origin) and then moved by position_mm. The world is the frame device
/// poses are in; an object with no placement has world = its file coordinates (a single-object
/// scene's world is its object's frame). Objects are static; a placement is a plain pose, so a
/// later version can change it between rounds.
struct Placement {
  geom::Vec3 position_mm{geom::Vec3::Zero()};   ///< translation, mm
  geom::Vec3 rotation_deg{geom::Vec3::Zero()};  ///< XYZ Euler angles, degrees
  geom::Pose pose() const;                      ///< object file coordinates → world
};

/// A material ([force] is the default one, [object.material] overrides it per object).
struct Material {
  rt::ForceLawConfig law = rt::DefaultForceLawConfig();  ///< eq. (1) or a spring
  double damping_N_s_per_mm = 0;                         ///< damping along the contact normal
  rt::FrictionConfig friction;                           ///< static and dynamic friction (none by default)
};

/// One touchable object of a scene: a body, its placement and its material.
struct ObjectSpec {
  std::string name;     ///< [[object]] name (default: "object N", N from 1 in file order)
  BodySpec body;        ///< its mesh or generated shape
  Placement placement;  ///< where it sits in the world
  Material material;    ///< how it feels
};

/// Objects a scene may hold ([[object]] entries).
inline constexpr std::size_t kMaxSceneObjects = 1024;

/// The device: a simulated one (a script) or a real one behind the UDP bridge.
struct DeviceSpec {
  std::string kind = "simulated";                          ///< "simulated" or "udp"
  rt::UdpDeviceConfig udp = rt::DefaultUdpDeviceConfig();  ///< kind = "udp" (its key is read when the run opens it)
  /// kind = "udp", auth = "hmac": the shared key's file ("" = the run makes a key of its own and
  /// writes it to bridge_key_path(), for the driver to read)
  std::string key_file;
  std::string script = "builtin";          ///< "builtin" or a trajectory file (t + 16 numbers a line)
  bool target_top = true;                  ///< builtin: touch the object's highest point along +z
  geom::Vec3 target{geom::Vec3::Zero()};   ///< builtin: surface point, object frame, mm (target_top false)
  geom::Vec3 normal{geom::Vec3::UnitZ()};  ///< builtin: approach against this outward normal
  double press_mm = 3;                     ///< builtin: press depth, mm
  double slide_mm = 20;                    ///< builtin: slide length, mm
  rt::VirtualUser user;                    ///< spring-damper hand reacting to the force
  bool repeat = false;                     ///< replay the script from its start each time it ends
  /// The wrench ([device] dof, torque_limit_nm, tcp_mm): 3-DOF by default; the tool centre point
  /// is the probe's tip unless tcp_mm is given (tcp_auto).
  rt::WrenchConfig wrench;
  bool tcp_auto = true;  ///< tool centre point = the probe's tip (Scene::probe_tip or its lowest vertex)
};

/// Everything a run needs, with defaults from the libraries' Default…() functions.
struct Scene {
  std::string file;  ///< the scene file (for messages)
  BodySpec probe;    ///< the hand (or tool) the device moves
  BodySpec object;   ///< the touched object (of several: the first)
  /// [[object]]: every object with its placement and material, in file order (empty for a scene
  /// with one [object]: then `object`, `law`, `friction` and `interp.damping_N_s_per_mm` are it, at
  /// the world's origin). The parser also sets `object` and the material fields to the first
  /// object's, for code that knows one object. Use scene_objects() to read either form.
  std::vector<ObjectSpec> objects;
  bool probe_tip_auto = true;                         ///< fingertip = probe's lowest vertex along the approach
  geom::Vec3 probe_tip{geom::Vec3::Zero()};           ///< fingertip, probe file coordinates, mm
  geom::Vec3 probe_rotation_deg{geom::Vec3::Zero()};  ///< probe orientation (XYZ Euler, about the tip)
  geom::TreeConfig tree = geom::DefaultTreeConfig();  ///< leaf size
  bool tree_cache = true;                             ///< read/write trees in the tree cache
  /// Distribution: the sphere layer whose spheres are dealt in blocks; geom::kFree = chosen by
  /// geom::choose_split() for the scene and worker count ("auto").
  std::uint32_t layer = geom::kFree;
  std::uint32_t block_size = 0;                         ///< layer spheres per block; 0 = chosen with the layer ("auto")
  geom::Mapping mapping = geom::Mapping::block_cyclic;  ///< how blocks are dealt to workers
  int workers = 2;                                      ///< in-process workers (0 = collide in the collision thread)
  std::vector<std::string> endpoints;                   ///< worker daemons (overrides `workers`)
  std::string server_key;   ///< CURVE: the workers' public key file (resolved path; "" = plain)
  std::string client_key;   ///< CURVE: this client's key pair PREFIX (PREFIX.key, PREFIX.pub)
  double deadline_ms = 50;  ///< scatter-gather round deadline, ms
  int down_after = 3;       ///< missed deadlines before a worker is marked down
  /// Blocks the collision thread answers itself each round (net::ScatterConfig::assist_blocks);
  /// -1 = "auto": kAutoAssistBlocks with worker daemons, 0 (off) with in-process workers.
  int assist_blocks = -1;
  /// Every block also on a second worker, dealt each round by the work reported
  /// (net::ScatterConfig::replicas): evener rounds past 8 workers, a down worker's blocks answered
  /// at once; twice the workers' memory.
  bool replicas = false;
  double collision_rate_hz = 0;     ///< cap on collision rounds per second (0 = as fast as possible)
  int approx_layer = geom::kExact;  ///< kExact, or a sphere layer for the approximate mode
  /// [collision] coherent: the collision thread's own queries and the in-process workers' carry
  /// certificates between rounds (geom::CoherentCollider; the same pairs, faster at haptic
  /// speeds); worker daemons follow their own `coherent` config key
  bool coherent = true;
  rt::HapticLoopConfig haptic = rt::DefaultHapticLoopConfig();  ///< servo loop
  /// stack of every thread run starts ([haptic] thread_stack_kb); 0 = glibc's default
  std::size_t thread_stack_bytes = 1 << 20;
  rt::ForceLawConfig law = rt::DefaultForceLawConfig();  ///< eq. (1) or spring (the object's material)
  rt::FrictionConfig friction;  ///< the object's material's friction ([force], overridden by [object.material]); none by default
  rt::SaturationConfig saturation = rt::DefaultSaturationConfig();  ///< device limits
  rt::InterpolatorConfig interp = rt::DefaultInterpolatorConfig();  ///< between contact updates
  geom::ContactConfig contact = geom::DefaultContactConfig();       ///< contact model (patch or paper)
  rt::PassivityConfig passivity = rt::DefaultPassivityConfig();     ///< energy guard in the servo
  DeviceSpec device;                                                ///< simulated device
  double duration_s = 6;                                            ///< run length (the built-in script takes 5 s)
  std::string out_dir;                                              ///< run directory ("" = runs/TIMESTAMP)
  bool write_trace = true;                                          ///< ticks.csv and rounds.csv in the run directory
  bool write_perfetto = true;                                       ///< trace.json (Perfetto / chrome://tracing)
  bool write_ply = true;        ///< contact.ply: the contact state at peak penetration
  std::string status = "auto";  ///< status line: auto, tty, plain, off
};

/// The scene's objects: `objects`, or (a scene of one [object]) that object at the world's origin
/// with the scene's [force] material.
std::vector<ObjectSpec> scene_objects(const Scene& s);

/// Gives the servo the scene's objects' materials (HapticServo::set_objects, in scene_objects()
/// order); errors name the object.
Status set_servo_materials(rt::HapticServo& servo, const Scene& s);

/// The tool centre point torques are taken about, probe file coordinates, mm: `[device] tcp_mm`,
/// or the probe's tip (the grip's origin, probe_grip()).
geom::Vec3 tool_point(const Scene& s, const geom::Mesh& probe);

/// The defaults (a capsule fingertip against an icosphere: needs no download).
Scene DefaultScene();

/// A scene file is a text file of at most this many bytes.
inline constexpr std::uint64_t kMaxSceneBytes = 1u << 20;
/// Reads and checks a scene file (a regular file of at most kMaxSceneBytes); errors name the
/// file, line and field.
Result<Scene> load_scene(const std::string& path);

/// Parses scene text; `name` is used in messages and `dir` resolves relative mesh paths.
Result<Scene> parse_scene(const std::string& text, const std::string& name, const std::string& dir);

/// Directory of the model set: $ST_MODEL_DIR, else .cache/models next to the executable's
/// source tree, else ./.cache/models.
std::string model_dir();

/// The built-in script: the probe's fingertip (scene tip, or its lowest vertex along the approach)
/// approaches the object's surface point (scene target, or its extreme vertex along the normal)
/// against the normal, presses, slides and releases (rt::builtin_press_slide moves the fingertip).
rt::Trajectory builtin_script(const Scene& s, const geom::Mesh& probe, const geom::Mesh& object);
/// The same over a scene of several objects (scene_objects(s) order, meshes as loaded): the
/// target is a world point (the extreme vertex along the normal over every placed object, or the
/// scene's target, read in the world frame).
rt::Trajectory builtin_script(const Scene& s, const geom::Mesh& probe, std::span<const geom::Mesh* const> objects);
/// The probe as the device holds it: probe file coordinates to the tool frame (the fingertip at
/// the origin, the scene's probe rotation). A device pose is Trans(tip position) · Rot · grip.
geom::Pose probe_grip(const Scene& s, const geom::Mesh& probe);

/// Where a run that makes its own bridge key writes it: RUN_DIR/bridge.key (mode 0600).
std::string bridge_key_path(const std::string& run_dir);
/// The UDP bridge's settings for a run writing to `run_dir`: the scene's [device] fields, the
/// force and torque limits (the saturation's peak; torque_limit_nm for a 6-DOF device, else no
/// torque) and, with auth = "hmac", the key: read from key_file, or (none given) made for this
/// run and written to bridge_key_path(run_dir) when `make_key`, else read from there (the split
/// servo, after the run made it). Errors name the field or the file.
Result<rt::UdpDeviceConfig> udp_device_config(const Scene& s, const std::string& run_dir, bool make_key);

/// Loads (or generates) a body; errors name the scene field.
Result<geom::Mesh> load_body(const BodySpec& spec, const std::string& field);

/// What a run records in its segment about its scene and meshes (rt::SceneRef): `scene_path`
/// (absolute; "" = none, and a path longer than SceneRef::kMaxPath - 1 is recorded as none) and
/// the meshes' counts and geom::mesh_hash.
rt::SceneRef scene_ref(const std::string& scene_path, const geom::Mesh& probe, const geom::Mesh& object);
/// "" when `probe` and `object` are the meshes `ref` describes, else what differs (counts, or the
/// same counts and other coordinates or faces).
std::string compare_scene_ref(const rt::SceneRef& ref, const geom::Mesh& probe, const geom::Mesh& object);

}  // namespace st::engine
