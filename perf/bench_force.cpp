// spheretouch-bench force: force rendering quality, replayed in simulated time (deterministic: no
// sleeping, no wall clock except the cost fields). For each scene, contact model and loop:
//  * the servo's own code (rt::HapticServo: interpolator, passivity guard, saturator) ticks at
//    1 kHz against an rt::SimulatedDevice following the scene's script, open loop (the probe
//    follows the script) or closed loop (rt::VirtualUser: a spring-damper hand with mass that
//    yields to the force);
//  * the collision side runs collide() + ContactBuilder::build() at the pose of every C-th tick
//    and delivers the model C ticks later (--collision-ticks C, default 2).
// Models: "patch" = [contact] model = patch with the passivity guard (the shipped default);
// "paper" = the paper's nearest-face model (§3.6) without the guard (the pipeline before #13).
// Metrics (per scene × model × loop): per-tick force change dF and direction change over the
// slide (or every contact tick where there is no slide), direction flips > 45° within 20 ms,
// energy the commanded force put into the hand per contact cycle (Σ F_k·(x_{k+1} − x_k), the
// work of a zero-order-hold force on the moving device, mJ = N·mm), RMS of the force at >= 30 Hz
// while holding still (DFT, Parseval), depth error against the analytic depth (box, sphere),
// pop-through on the 1 mm plate, and the collision + contact cost per round.
// A separate figure times the contact models at the perf poses (~100 to ~1,500 contacts).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <sstream>

#include "engine/scene.hpp"
#include "bench.hpp"
#include "bench_tables_common.hpp"
#include "geom/collide.hpp"
#include "geom/contact.hpp"
#include "geom/primitives.hpp"
#include "rt/haptic_servo.hpp"
#include "rt/simulated_device.hpp"

namespace st::bench {
namespace {

[[noreturn]] void die(const std::string& msg) {
  std::fprintf(stderr, "spheretouch-bench force: %s\n", msg.c_str());
  throw CLI::RuntimeError(2);
}

constexpr double kPi = 3.14159265358979323846;
constexpr std::int64_t kTickNs = 1'000'000;  // 1 kHz servo
constexpr double kDirMinN = 0.05;            // directions are compared only above this force, N
constexpr double kPopDepthMm = 0.5;          // a force vanishing deeper than this is a pop-through, mm

/// A scene: bodies, a script of probe poses and the windows the metrics look at.
struct ForceScene {
  std::string name;
  Body probe, object;
  rt::Trajectory script;
  double slide_t0 = 0, slide_t1 = 0;                   // dF / angle window, s (empty: every contact tick)
  double still_t0 = 0, still_t1 = 0;                   // holding still, s (empty: no still figure)
  std::function<double(const geom::Vec3&)> depth_ref;  // analytic depth of the probe at a position (null: unknown)
  bool plate = false;                                  // pop-through: device below the plate's top while over it
};

Body generated(const std::string& label, geom::Mesh mesh) {
  Body b;
  b.label = label;
  b.mesh = std::move(mesh);
  auto t = geom::SphereTree::build(b.mesh);
  if (!t) die(label + ": " + t.error());
  b.tree = std::move(t).value();
  return b;
}

/// Script builder: keys of probe positions (identity orientation) at increasing times.
struct Keys {
  rt::Trajectory tr;
  double t = 0;
  void at(const geom::Vec3& p) {  // the first key
    rt::TimedPose k;
    k.t_s = t;
    k.pose.translation() = p;
    tr.keys.push_back(k);
  }
  void to(const geom::Vec3& p, double dt) {  // move to p in dt seconds
    t += dt;
    at(p);
  }
  void hold(double dt) { to(tr.keys.back().pose.translation(), dt); }
  geom::Vec3 last() const { return tr.keys.back().pose.translation(); }
};

/// Ball (r 10 mm) on a 40 mm box's top face: presses, a slide on the face, a still hold.
ForceScene box_scene(bool quick) {
  ForceScene s;
  s.name = "box";
  s.object = generated("box40", geom::make_box({40, 40, 40}));  // top face z = +20
  s.probe = generated("ball10", geom::make_icosphere(10, 16));
  const double touch = 30;  // centre height at which the ball touches the face
  Keys k;
  k.at({-10, 0, touch + 5});
  for (double d : quick ? std::vector<double>{2, 10} : std::vector<double>{0.5, 2, 5, 10}) {
    k.to({-10, 0, touch - d}, 0.3);
    k.hold(0.3);
    k.to({-10, 0, touch + 0.5}, 0.3);
  }
  k.to({-10, 0, touch - 3}, 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  k.to({10, 0, touch - 3}, quick ? 1.0 : 2.0);  // 10 (quick: 20) mm/s on the face
  s.slide_t1 = k.t;
  k.hold(1.0);
  s.still_t0 = k.t - 0.8;
  s.still_t1 = k.t;
  k.to({10, 0, touch + 5}, 0.3);
  k.hold(0.3);
  s.script = k.tr;
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 10.0 - (c.z() - 20.0)); };
  return s;
}

/// Ball (r 10) on a ball (R 20): presses along +z, a slide along a great circle, a still hold.
ForceScene sphere_scene(bool quick) {
  ForceScene s;
  s.name = "sphere";
  s.object = generated("ball20", geom::make_icosphere(20, 16));
  s.probe = generated("ball10", geom::make_icosphere(10, 16));
  auto on = [](double dist, double deg) {
    return geom::Vec3(dist * std::sin(deg * kPi / 180), 0, dist * std::cos(deg * kPi / 180));
  };
  Keys k;
  k.at(on(35, -15));
  for (double d : quick ? std::vector<double>{2, 10} : std::vector<double>{0.5, 2, 5, 10}) {
    k.to(on(30 - d, -15), 0.3);
    k.hold(0.3);
    k.to(on(30.5, -15), 0.3);
  }
  k.to(on(27, -15), 0.3);
  k.hold(0.2);
  s.slide_t0 = k.t;
  const double arc_s = 27 * 30 * kPi / 180 / 10.0;  // 30° at 10 mm/s
  for (int deg = -14; deg <= 15; ++deg) k.to(on(27, deg), arc_s / 30 * (quick ? 0.5 : 1.0));
  s.slide_t1 = k.t;
  k.hold(1.0);
  s.still_t0 = k.t - 0.8;
  s.still_t1 = k.t;
  k.to(on(35, 15), 0.3);
  k.hold(0.3);
  s.script = k.tr;
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 30.0 - c.norm()); };
  return s;
}

/// A 1 mm plate (60 × 60 mm, top at z = +0.5) crossed by a fingertip ball (r 5) at 100 mm/s.
ForceScene plate_scene() {
  ForceScene s;
  s.name = "plate";
  s.object = generated("plate1", geom::make_box({60, 60, 1}));
  s.probe = generated("ball5", geom::make_icosphere(5, 12));
  Keys k;
  k.at({0.3, -0.2, 10.5});
  k.to({0.3, -0.2, -20.0}, 0.305);  // 100 mm/s down, through the plate
  k.hold(0.2);
  k.to({0.3, -0.2, 10.5}, 0.305);  // and back up
  k.hold(0.3);
  s.script = k.tr;
  s.plate = true;
  // Depth below the side it was entered by (the top), while over the plate.
  s.depth_ref = [](const geom::Vec3& c) { return std::max(0.0, 0.5 - (c.z() - 5.0)); };
  return s;
}

/// The hand on a model-set object: the built-in approach / press 3 mm / hold 0.5 s (still) /
/// slide 20 mm in 2 s (0.01 mm per tick) / release script.
ForceScene hand_scene(const std::string& name, const std::string& probe_path, const std::string& object_path) {
  ForceScene s;
  s.name = name;
  s.probe = load_body(probe_path);
  s.object = load_body(object_path);
  s.script = press_slide_script(s.probe.mesh, s.object.mesh, 5.0);
  s.still_t0 = 1.7;  // the press ends at 1.5 s; 0.2 s to settle
  s.still_t1 = 2.0;
  s.slide_t0 = 2.0;
  s.slide_t1 = 4.0;
  return s;
}

struct Model {
  std::string name;
  geom::ContactConfig contact;
  rt::PassivityConfig passivity;
};

struct Tick {
  Eigen::Vector3d x, f;
  double pd = 0;
};

/// One replay; returns per-tick records and the per-round costs.
struct Replay {
  std::vector<Tick> ticks;
  std::vector<double> collide_us, contact_us, contacts;  // in-contact rounds
};

Replay replay(const ForceScene& s, const Model& model, bool closed, int C) {
  rt::VirtualUser user;
  user.enabled = closed;
  const int n = int(std::ceil(s.script.duration_s() * 1000.0)) + 1;
  rt::SimulatedDevice dev(s.script, user, std::size_t(n) + 1);
  auto poses = std::make_unique<rt::TripleBuffer<rt::PoseSample>>();
  auto models = std::make_unique<rt::TripleBuffer<geom::ContactModel>>();
  rt::HapticServo servo(dev, *poses, *models, rt::ForceLaw{}, rt::DefaultInterpolatorConfig(),
                        rt::DefaultSaturationConfig(), nullptr, model.passivity, 1e-3);
  geom::ContactBuilder builder(model.contact);
  builder.prepare(s.probe.mesh, s.object.mesh);
  geom::CollideScratch sc;
  geom::CollideResult r;
  Replay out;
  out.ticks.reserve(std::size_t(n));
  geom::ContactModel pending{};
  bool have_pending = false;
  std::uint64_t seq = 0;
  for (int k = 0; k < n; ++k) {
    const std::int64_t t = 1'000'000'000 + std::int64_t(k) * kTickNs;
    if (have_pending && k % C == 0) {
      models->write(pending);
      have_pending = false;
    }
    rt::TickInfo info;
    info.tick = info.deadline_index = std::uint64_t(k);
    info.deadline_ns = info.woke_ns = t;
    info.period_ns = kTickNs;
    servo.tick(info);
    const rt::ForceRecord& rec = dev.records().back();
    out.ticks.push_back({rec.position, rec.force_N, servo.interpolator().state().penetration_mm});
    if (k % C == 0) {
      poses->update();
      const rt::PoseSample ps = poses->output();
      const geom::Pose pose = geom::to_eigen(ps.pose);
      const auto t0 = std::chrono::steady_clock::now();
      geom::collide(s.probe.mesh, s.probe.tree, s.object.mesh, s.object.tree, pose, {}, sc, r);
      const auto t1 = std::chrono::steady_clock::now();
      pending = builder.build(s.probe.mesh, s.object.mesh, pose, r.pairs);
      const auto t2 = std::chrono::steady_clock::now();
      pending.seq = ++seq;
      pending.pose_seq = ps.seq;
      pending.pose_sampled_ns = ps.sampled_ns;
      pending.published_ns = t;
      have_pending = true;
      if (!r.pairs.empty()) {
        out.collide_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
        out.contact_us.push_back(std::chrono::duration<double, std::micro>(t2 - t1).count());
        out.contacts.push_back(pending.contacts);
      }
    }
  }
  return out;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / kPi;
}

/// RMS of the part of x (per component, linear trend removed) at >= f_lo Hz, samples at 1 kHz
/// (DFT, Parseval).
double rms_above(const std::vector<Eigen::Vector3d>& x, double f_lo) {
  const std::size_t N = x.size();
  if (N < 16) return 0;
  double power = 0;
  for (int c = 0; c < 3; ++c) {
    // Remove the least-squares line first: a slow drift (the saturator's thermal ceiling
    // settling) is not an oscillation, but a ramp's DFT leaks into every frequency.
    double st = 0, sy = 0, stt = 0, sty = 0;
    for (std::size_t i = 0; i < N; ++i) {
      const double t = double(i), y = x[i](c);
      st += t, sy += y, stt += t * t, sty += t * y;
    }
    const double den = double(N) * stt - st * st;
    const double slope = den != 0 ? (double(N) * sty - st * sy) / den : 0.0, icpt = (sy - slope * st) / double(N);
    for (std::size_t k = 1; k <= N / 2; ++k) {
      if (double(k) * 1000.0 / double(N) < f_lo) continue;
      double re = 0, im = 0;
      for (std::size_t i = 0; i < N; ++i) {
        const double ph = 2 * kPi * double(k) * double(i) / double(N);
        const double y = x[i](c) - (icpt + slope * double(i));
        re += y * std::cos(ph);
        im -= y * std::sin(ph);
      }
      power += (re * re + im * im) / (double(N) * double(N)) * (2 * k == N ? 1.0 : 2.0);
    }
  }
  return std::sqrt(power);
}

struct Figures {
  std::string scene, model, loop;
  double dF_p99 = 0, dF_max = 0, angle_p99 = 0, flips45_per_s = 0, energy_per_cycle = 0, energy_cycle_max = 0;
  double still_rms = -1, depth_err = -1, depth_err_rms = -1;
  int popthrough = -1, cycles = 0;
  double round_us_p50 = 0, collide_us_p50 = 0, contact_us_p50 = 0, contacts_p50 = 0;
  std::size_t ticks = 0, contact_ticks = 0;
};

Figures measure(const ForceScene& s, const Replay& rp) {
  Figures fg;
  const auto& T = rp.ticks;
  fg.ticks = T.size();
  auto t_of = [](std::size_t i) { return double(i) * 1e-3; };
  const bool window = s.slide_t1 > s.slide_t0;
  std::vector<double> dF, ang;
  int flips = 0;
  bool flipping = false;
  for (std::size_t i = 1; i < T.size(); ++i) {
    const bool on = T[i].f.norm() > 0 || T[i - 1].f.norm() > 0;
    if (T[i].f.norm() > 0) ++fg.contact_ticks;
    // Flips: direction against 20 ms earlier, counted once per event.
    bool flip = false;
    if (i >= 20 && T[i].f.norm() > kDirMinN && T[i - 20].f.norm() > kDirMinN)
      flip = angle_deg(T[i].f, T[i - 20].f) > 45;
    if (flip && !flipping) ++flips;
    flipping = flip;
    if (!on || (window && (t_of(i) < s.slide_t0 || t_of(i) > s.slide_t1))) continue;
    dF.push_back((T[i].f - T[i - 1].f).norm());
    if (T[i].f.norm() > kDirMinN && T[i - 1].f.norm() > kDirMinN) ang.push_back(angle_deg(T[i].f, T[i - 1].f));
  }
  fg.dF_max = dF.empty() ? 0 : *std::max_element(dF.begin(), dF.end());
  fg.dF_p99 = quantile(dF, 0.99);
  fg.angle_p99 = quantile(ang, 0.99);
  fg.flips45_per_s = fg.contact_ticks ? flips / (double(fg.contact_ticks) * 1e-3) : 0;
  // Energy per contact cycle (force on → off).
  std::vector<double> cyc;
  double e = 0;
  bool on = false;
  for (std::size_t i = 0; i + 1 < T.size(); ++i) {
    const bool f_on = T[i].f.norm() > 0;
    if (f_on && !on) e = 0;
    if (f_on) e += T[i].f.dot(T[i + 1].x - T[i].x);
    if (!f_on && on) cyc.push_back(e);
    on = f_on;
  }
  if (on) cyc.push_back(e);  // a cycle still open at the end
  fg.cycles = int(cyc.size());
  if (!cyc.empty()) {
    double sum = 0;
    for (double c : cyc) sum += c;
    fg.energy_per_cycle = sum / double(cyc.size());
    fg.energy_cycle_max = *std::max_element(cyc.begin(), cyc.end());
  }
  if (s.still_t1 > s.still_t0) {
    std::vector<Eigen::Vector3d> f;
    for (std::size_t i = std::size_t(s.still_t0 * 1000); i < std::min(T.size(), std::size_t(s.still_t1 * 1000)); ++i)
      f.push_back(T[i].f);
    fg.still_rms = rms_above(f, 30.0);
  }
  if (s.depth_ref && !s.plate) {
    double worst = 0, sq = 0;
    std::size_t n = 0;
    for (const Tick& t : T) {
      const double ref = s.depth_ref(t.x);
      if (!(ref > 0 && ref <= 10.01) || !(t.f.norm() > 0)) continue;
      worst = std::max(worst, std::abs(t.pd - ref));
      sq += (t.pd - ref) * (t.pd - ref);
      ++n;
    }
    fg.depth_err = worst;
    fg.depth_err_rms = n ? std::sqrt(sq / double(n)) : 0;
  }
  if (s.depth_ref) {
    // Pop-through events: while the device is in (plate: below its top and over it), the force
    // starts pushing it toward the far side, or vanishes deeper than kPopDepthMm (half the plate:
    // past it a nearest-surface model pushes the probe on through). A force the passivity guard
    // takes away in the last tenths of a millimetre of a fast release is not a pop-through.
    fg.popthrough = 0;
    for (std::size_t i = 1; i < T.size(); ++i) {
      const double ref = s.depth_ref(T[i].x);
      const bool over = !s.plate || (std::abs(T[i].x.x()) < 30 && std::abs(T[i].x.y()) < 30);
      if (!over || !(ref > 0)) continue;
      const Eigen::Vector3d out = s.plate ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d(T[i].x.normalized());
      const double push_prev = s.plate ? T[i - 1].f.dot(out) : T[i - 1].f.norm();
      const double push = s.plate ? T[i].f.dot(out) : T[i].f.norm();
      const bool wrong_way = s.plate && push < -1e-9 && !(push_prev < -1e-9);
      const bool vanished = ref > kPopDepthMm && push_prev > 0 && !(push > 0);
      if (wrong_way || vanished) ++fg.popthrough;
    }
  }
  auto med = [](std::vector<double> v) { return quantile(v, 0.5); };
  std::vector<double> round;
  for (std::size_t i = 0; i < rp.collide_us.size(); ++i) round.push_back(rp.collide_us[i] + rp.contact_us[i]);
  fg.round_us_p50 = med(round);
  fg.collide_us_p50 = med(rp.collide_us);
  fg.contact_us_p50 = med(rp.contact_us);
  fg.contacts_p50 = med(rp.contacts);
  return fg;
}

void write_trace(const std::string& path, const Replay& rp, const ForceScene& s) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) die(path + ": cannot create");
  std::fputs("t_s,x,y,z,fx,fy,fz,f,pd_mm,depth_ref_mm\n", f);
  for (std::size_t i = 0; i < rp.ticks.size(); ++i) {
    const Tick& t = rp.ticks[i];
    std::fprintf(f, "%.3f,%.5f,%.5f,%.5f,%.6f,%.6f,%.6f,%.6f,%.5f,%.5f\n", double(i) * 1e-3, t.x.x(), t.x.y(), t.x.z(),
                 t.f.x(), t.f.y(), t.f.z(), t.f.norm(), t.pd, s.depth_ref ? s.depth_ref(t.x) : std::nan(""));
  }
  if (std::fclose(f) != 0) die(path + ": write failed");
}

/// Contact model cost at the perf poses: cold (a fresh builder) and warm (after 100 rounds
/// sliding 0.01 mm per round into the pose), against collide() in the same loop. The warm rounds
/// repeat the pose, or with slide_mm > 0 move the probe that far along x each round, through it
/// (centred on it).
struct Cost {
  std::uint32_t contacts = 0;
  std::string model;
  double collide_us = 0;    ///< collide() median, timed in the warm loop (the rounds the contact model follows)
  double cold_us = 0;       ///< contact model, a fresh builder (no history), median
  double warm_us = 0;       ///< contact model with history, median
  double warm_mean_us = 0;  ///< and its mean (the rounds that look for new contact regions cost more)
};

std::vector<Cost> contact_cost(const Body& probe, const Body& object, const std::vector<TaggedPose>& poses,
                               const std::vector<Model>& models, int runs, double slide_mm) {
  std::vector<Cost> out;
  geom::CollideScratch sc;
  geom::CollideResult r;
  using clock = std::chrono::steady_clock;
  auto us = [](clock::time_point a, clock::time_point b) {
    return std::chrono::duration<double, std::micro>(b - a).count();
  };
  for (const TaggedPose& tp : poses) {
    for (const Model& m : models) {
      Cost c;
      c.model = m.name;
      std::vector<double> col, cold, warm;
      for (int k = 0; k < runs; ++k) {
        geom::ContactBuilder fresh(m.contact);
        fresh.prepare(probe.mesh, object.mesh);
        geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, tp.pose, {}, sc, r);
        const auto t1 = clock::now();
        const geom::ContactModel cm = fresh.build(probe.mesh, object.mesh, tp.pose, r.pairs);
        const auto t2 = clock::now();
        cold.push_back(us(t1, t2));
        c.contacts = cm.contacts;
      }
      // Warm: the builder follows a slide onto the pose (history), each round a collide() then a
      // model, as in the collision thread; both timed here, so the share compares rounds alike
      // (collide() right after a fresh builder's set-up runs on evicted caches and looks slower).
      geom::ContactBuilder b(m.contact);
      b.prepare(probe.mesh, object.mesh);
      const double start = -0.5 * runs * slide_mm;  // the timed rounds' first offset
      for (int k = 0; k < 100 + runs; ++k) {
        geom::Pose p = tp.pose;
        p.translation().x() += start + double(k - 100) * (k < 100 ? 0.01 : slide_mm);
        const auto t0 = clock::now();
        geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, p, {}, sc, r);
        const auto t1 = clock::now();
        (void)b.build(probe.mesh, object.mesh, p, r.pairs);
        const auto t2 = clock::now();
        if (k >= 100) {
          col.push_back(us(t0, t1));
          warm.push_back(us(t1, t2));
        }
      }
      c.collide_us = quantile(col, 0.5);
      c.cold_us = quantile(cold, 0.5);
      c.warm_us = quantile(warm, 0.5);
      c.warm_mean_us = std::accumulate(warm.begin(), warm.end(), 0.0) / double(warm.size());
      out.push_back(c);
    }
  }
  return out;
}

}  // namespace

void add_force(CLI::App& app) {
  struct Args {
    std::string scenes = "box,sphere,plate,hand_elephant,hand_armadillo", models = "paper,patch", trace_dir, poses;
    int collision_ticks = 2, cost_runs = 30;
    double cost_slide_mm = 0;
    bool json = false, quick = false;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "force",
      "Force rendering quality in simulated time: per scene, contact model (paper, patch) and loop (open, "
      "closed with the simulated hand): force steps, direction changes and flips, energy per contact "
      "cycle, oscillation while holding still, depth error, pop-through, cost per round");
  cmd->add_option("--scenes", a->scenes, "box, sphere, plate, hand_elephant, hand_armadillo (model set)")->capture_default_str();
  cmd->add_option("--models", a->models, "contact models: paper (no passivity guard), patch (the default, guarded)")
      ->capture_default_str();
  cmd->add_option("--collision-ticks", a->collision_ticks, "a collision round every C ticks, delivered C ticks later")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--trace-dir", a->trace_dir, "write force_<scene>_<model>_<loop>.csv (one line per tick) here");
  cmd->add_option("--poses", a->poses,
                  "pose file for the contact-cost figure (default perf/poses/hand_elephant.txt when present)");
  cmd->add_option("--cost-runs", a->cost_runs, "timed rounds per pose and model for the contact-cost figure")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--cost-slide", a->cost_slide_mm,
                  "for the contact-cost figure, move the probe this many mm along x each timed round, through "
                  "each pose (0: the timed rounds repeat the pose)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd->add_flag("--quick", a->quick, "shorter scripts, fewer cost runs (CI smoke run)");
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->callback([a] {
    std::vector<Model> models;
    std::stringstream ms(a->models);
    for (std::string m; std::getline(ms, m, ',');) {
      Model mm{m, geom::DefaultContactConfig(), rt::DefaultPassivityConfig()};
      auto kind = geom::parse_contact_model(m);
      if (!kind) die("--models: " + kind.error());
      mm.contact.model = kind.value();
      mm.passivity.enabled = kind.value() == geom::ContactModelKind::patch;
      models.push_back(mm);
    }
    const std::string dir = engine::model_dir();
    std::vector<ForceScene> scenes;
    std::stringstream ss(a->scenes);
    for (std::string n; std::getline(ss, n, ',');) {
      std::fprintf(stderr, "force: loading scene %s\n", n.c_str());
      if (n == "box")
        scenes.push_back(box_scene(a->quick));
      else if (n == "sphere")
        scenes.push_back(sphere_scene(a->quick));
      else if (n == "plate")
        scenes.push_back(plate_scene());
      else if (n == "hand_elephant" || n == "hand_armadillo") {
        const std::string obj = n == "hand_elephant" ? "elephant.off" : "armadillo_L2.off";
        if (!std::filesystem::exists(dir + "/hand_L2.off") || !std::filesystem::exists(dir + "/" + obj)) {
          std::fprintf(stderr, "force: skipping %s: the model set is not in %s (scripts/models.sh)\n", n.c_str(),
                       dir.c_str());
          continue;
        }
        scenes.push_back(hand_scene(n, dir + "/hand_L2.off", dir + "/" + obj));
      } else {
        die("--scenes: unknown scene '" + n + "' (box, sphere, plate, hand_elephant, hand_armadillo)");
      }
    }
    if (!a->trace_dir.empty()) std::filesystem::create_directories(a->trace_dir);
    std::vector<Figures> all;
    for (const ForceScene& s : scenes)
      for (const Model& m : models)
        for (bool closed : {false, true}) {
          std::fprintf(stderr, "force: %s × %s, %s loop (%.1f s simulated)\n", s.name.c_str(), m.name.c_str(),
                       closed ? "closed" : "open", s.script.duration_s());
          const Replay rp = replay(s, m, closed, a->collision_ticks);
          Figures fg = measure(s, rp);
          fg.scene = s.name;
          fg.model = m.name;
          fg.loop = closed ? "closed" : "open";
          all.push_back(fg);
          if (!a->trace_dir.empty())
            write_trace(a->trace_dir + "/force_" + s.name + "_" + m.name + "_" + fg.loop + ".csv", rp, s);
        }
    // Contact-model cost at the perf poses.
    std::vector<Cost> costs;
    std::string pose_file = a->poses;
    if (pose_file.empty() && std::filesystem::exists("perf/poses/hand_elephant.txt"))
      pose_file = "perf/poses/hand_elephant.txt";
    if (!pose_file.empty() && std::filesystem::exists(dir + "/hand_L2.off") &&
        std::filesystem::exists(dir + "/elephant.off")) {
      std::fprintf(stderr, "force: contact-model cost at the poses of %s\n", pose_file.c_str());
      const Body hand = load_body(dir + "/hand_L2.off"), elephant = load_body(dir + "/elephant.off");
      costs = contact_cost(hand, elephant, read_tagged_poses(pose_file), models, a->quick ? 5 : a->cost_runs,
                           a->cost_slide_mm);
    }
    auto num = [](double v) {
      char b[64];
      if (!std::isfinite(v)) return std::string("null");
      std::snprintf(b, sizeof b, "%.6g", v);
      return std::string(b);
    };
    if (a->json) {
      std::printf("{\"collision_ticks\": %d, \"quick\": %s, \"scenes\": [", a->collision_ticks, a->quick ? "true" : "false");
      for (std::size_t i = 0; i < all.size(); ++i) {
        const Figures& f = all[i];
        std::printf(
            "%s\n  {\"scene\": \"%s\", \"model\": \"%s\", \"loop\": \"%s\", \"dF_p99_N\": %s, \"dF_max_N\": %s, "
            "\"angle_p99_deg\": %s, \"flips45_per_s\": %s, \"energy_per_cycle_mJ\": %s, \"energy_cycle_max_mJ\": %s, "
            "\"cycles\": %d, \"still_rms_30hz_N\": %s, \"depth_err_mm\": %s, \"depth_err_rms_mm\": %s, "
            "\"popthrough\": %s, \"round_us_p50\": %s, \"collide_us_p50\": %s, \"contact_us_p50\": %s, "
            "\"contacts_p50\": %s, \"ticks\": %zu, \"contact_ticks\": %zu}",
            i ? "," : "", f.scene.c_str(), f.model.c_str(), f.loop.c_str(), num(f.dF_p99).c_str(),
            num(f.dF_max).c_str(), num(f.angle_p99).c_str(), num(f.flips45_per_s).c_str(),
            num(f.energy_per_cycle).c_str(), num(f.energy_cycle_max).c_str(), f.cycles,
            f.still_rms < 0 ? "null" : num(f.still_rms).c_str(), f.depth_err < 0 ? "null" : num(f.depth_err).c_str(),
            f.depth_err_rms < 0 ? "null" : num(f.depth_err_rms).c_str(),
            f.popthrough < 0 ? "null" : std::to_string(f.popthrough).c_str(), num(f.round_us_p50).c_str(),
            num(f.collide_us_p50).c_str(), num(f.contact_us_p50).c_str(), num(f.contacts_p50).c_str(), f.ticks,
            f.contact_ticks);
      }
      std::printf("\n], \"contact_cost_slide_mm\": %s, \"contact_cost\": [", num(a->cost_slide_mm).c_str());
      for (std::size_t i = 0; i < costs.size(); ++i) {
        const Cost& c = costs[i];
        std::printf(
            "%s\n  {\"contacts\": %u, \"model\": \"%s\", \"collide_us_p50\": %s, \"contact_cold_us_p50\": %s, "
            "\"contact_warm_us_p50\": %s, \"contact_warm_us_mean\": %s, \"share_cold\": %s, \"share_warm\": %s, "
            "\"share_warm_mean\": %s}",
            i ? "," : "", c.contacts, c.model.c_str(), num(c.collide_us).c_str(), num(c.cold_us).c_str(),
            num(c.warm_us).c_str(), num(c.warm_mean_us).c_str(), num(c.cold_us / c.collide_us).c_str(),
            num(c.warm_us / c.collide_us).c_str(), num(c.warm_mean_us / c.collide_us).c_str());
      }
      std::printf("\n]}\n");
      return;
    }
    std::printf("force rendering in simulated time, a collision round every %d ticks (delivered %d ticks later)\n",
                a->collision_ticks, a->collision_ticks);
    std::printf("%-15s %-6s %-6s %9s %9s %9s %8s %10s %10s %9s %9s %5s %9s %9s\n", "scene", "model", "loop", "dF_p99_N",
                "dF_max_N", "angle_p99", "flips/s", "E/cycle_mJ", "E_max_mJ", "still_N", "depth_err", "pop", "round_us",
                "contact_us");
    for (const Figures& f : all)
      std::printf("%-15s %-6s %-6s %9.4f %9.4f %9.3f %8.2f %10.4f %10.4f %9s %9s %5s %9.1f %9.1f\n", f.scene.c_str(),
                  f.model.c_str(), f.loop.c_str(), f.dF_p99, f.dF_max, f.angle_p99, f.flips45_per_s, f.energy_per_cycle,
                  f.energy_cycle_max, f.still_rms < 0 ? "-" : num(f.still_rms).c_str(),
                  f.depth_err < 0 ? "-" : num(f.depth_err).c_str(),
                  f.popthrough < 0 ? "-" : std::to_string(f.popthrough).c_str(), f.round_us_p50, f.contact_us_p50);
    if (!costs.empty()) {
      std::printf(
          "\ncontact model cost at the perf poses (median µs, warm mean beside; share = contact / collide() of the "
          "warm rounds, which %s)\n",
          a->cost_slide_mm > 0 ? ("slide " + num(a->cost_slide_mm) + " mm a round through the pose").c_str()
                               : "repeat the pose");
      std::printf("%8s %-6s %10s %10s %10s %10s %8s %8s %8s\n", "contacts", "model", "collide", "cold", "warm",
                  "warm mean", "cold %", "warm %", "mean %");
      for (const Cost& c : costs)
        std::printf("%8u %-6s %10.1f %10.1f %10.1f %10.1f %7.0f%% %7.0f%% %7.0f%%\n", c.contacts, c.model.c_str(),
                    c.collide_us, c.cold_us, c.warm_us, c.warm_mean_us, 100 * c.cold_us / c.collide_us,
                    100 * c.warm_us / c.collide_us, 100 * c.warm_mean_us / c.collide_us);
    }
  });
}

}  // namespace st::bench
