// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench trade: the speed/accuracy trade, as a deterministic offline
// simulation in simulated time (no sleeping, no wall clock in the error axis).
//
// The probe follows the built-in press/slide script on the finest level's top, one pose per
// 1 ms tick. Reference: exact collide() on the finest level at EVERY tick, contact model built
// and force computed at that same tick (hold: F = law(PD)·FD of the current pose, no delay).
// Both use the contact model chosen by --contact (default patch, the shipped model: its force is
// continuous in the pose, so the reference does not jitter and smoothing is not counted as error;
// --contact paper gives the paper's nearest-face model, as in the first harness runs).
// A test configuration (mesh level, collision rate cap, interpolation) runs the same code paths
// as the servo: collide() on its level at the pose of every k-th tick (k = 1000 Hz / rate), the
// ContactModel (ContactBuilder) delivered one tick later to an rt::Interpolator of the chosen
// method, then the rt::Saturator. Error axis: |F_test - F_ref| per tick, RMS and max over the run,
// N; contact recall: of the finest level's colliding object faces at a tick, the fraction whose
// ancestor (Loop subdivision: face f of level k is faces 4f..4f+3 of level k+1) is in the contact
// set the haptic side holds at that tick, pooled over ticks. Cost axis: collide() latency
// (median over in-contact poses of the script, warm, this thread), collision time per haptic
// tick (latency / k) and the memory the configuration holds (object + probe meshes and trees).
// Leaf size changes cost only: results are exact for any leaf size (checked here).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>

#include "bench.hpp"
#include "bench_tables_common.hpp"
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/rt/interpolator.hpp>
#include <spheretouch/rt/saturation.hpp>

namespace st::bench {
namespace {

/// Exact pairs at every tick of the script for one level.
struct LevelRun {
  Body body;
  std::vector<std::vector<geom::FacePair>> pairs;    // per tick
  std::vector<std::vector<std::uint32_t>> objfaces;  // per tick, sorted distinct object faces
  double latency_us = 0;                             // median collide() over sampled in-contact ticks
  std::size_t memory = 0;                            // bytes: meshes + trees (probe and object)
  int depth_below_finest = 0;                        // Loop levels between it and the finest
};

/// Median collide() time (µs) over `ticks`, each the fastest of 5 warm runs (the machine is shared:
/// the minimum drops preemptions by other processes).
double time_collide(const Body& probe, const Body& object, const std::vector<geom::Pose>& poses,
                    const std::vector<std::size_t>& ticks, std::vector<std::vector<geom::FacePair>>* pairs_out) {
  geom::CollideScratch sc;
  geom::CollideResult r;
  geom::CollideConfig opt;
  opt.sort_pairs = true;
  std::vector<double> us;
  for (std::size_t i : ticks) {
    double t5[5];
    for (double& t : t5) {
      const auto t0 = std::chrono::steady_clock::now();
      geom::collide(probe.mesh, probe.tree, object.mesh, object.tree, poses[i], opt, sc, r);
      t = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
    }
    us.push_back(*std::min_element(t5, t5 + 5));
    if (pairs_out) pairs_out->push_back(r.pairs);
  }
  return quantile(us, 0.5);
}

struct Trace {
  std::vector<Eigen::Vector3d> force;
  double recall = 1;
};

/// Forces of one configuration over the script (see the file comment). k = ticks per round;
/// `exact_every_tick` = the reference (model built and used at the same tick).
Trace simulate(const geom::ContactConfig& contact, const Body& probe, const LevelRun& lv,
               const std::vector<geom::Pose>& poses, int k, rt::InterpMode mode, bool exact_every_tick,
               const LevelRun* finest) {
  rt::InterpolatorConfig ic = rt::DefaultInterpolatorConfig();
  ic.mode = mode;
  rt::Interpolator interp(rt::ForceLaw{}, ic);
  rt::Saturator sat(rt::DefaultSaturationConfig());
  geom::ContactBuilder builder(contact);
  Trace out;
  out.force.resize(poses.size());
  geom::ContactModel pending{};
  std::size_t pending_tick = 0, in_use_tick = SIZE_MAX;
  bool have_pending = false;
  std::uint64_t seq = 0;
  double hits = 0, total = 0;
  const int shift = 2 * lv.depth_below_finest;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const std::int64_t t = std::int64_t(i + 1) * kTickNs;
    if (exact_every_tick) {
      geom::ContactModel m = builder.build(probe.mesh, lv.body.mesh, poses[i], lv.pairs[i]);
      m.seq = ++seq;
      interp.on_model(m, t);
      in_use_tick = i;
    } else if (have_pending && pending_tick + 1 == i) {
      interp.on_model(pending, t);
      in_use_tick = pending_tick;
      have_pending = false;
    }
    out.force[i] = sat.apply(interp.force(poses[i], t), i ? 1e-3 : 0.0);
    if (!exact_every_tick && i % std::size_t(k) == 0) {
      pending = builder.build(probe.mesh, lv.body.mesh, poses[i], lv.pairs[i]);
      pending.seq = ++seq;
      pending_tick = i;
      have_pending = true;
    }
    if (finest) {  // recall of the finest level's colliding object faces at tick i
      const auto& ref = finest->objfaces[i];
      total += double(ref.size());
      if (in_use_tick != SIZE_MAX) {
        const auto& use = lv.objfaces[in_use_tick];
        for (std::uint32_t g : ref) hits += std::binary_search(use.begin(), use.end(), g >> shift);
      }
    }
  }
  out.recall = total > 0 ? hits / total : 1.0;
  return out;
}

}  // namespace

void add_trade(CLI::App& app) {
  struct Args {
    std::string contact = "patch";
    std::string probe, levels, csv, trace_csv, leafs = "4,8,16,32,64", rates = "1000,250,60,25",
                                               interps = "hold,paper,plane";
    double seconds = 5;
    int samples = 200;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd =
      app.add_subcommand("trade",
                         "Speed/accuracy trade: leaf size, mesh level, collision rate cap, interpolation vs an exact "
                         "every-tick reference (offline, simulated time)");
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required();
  cmd->add_option("--contact", a->contact, "contact model of the reference and the configurations: patch or paper")
      ->check(CLI::IsMember({"patch", "paper"}))
      ->capture_default_str();
  cmd->add_option("--levels", a->levels,
                  "object meshes coarse to fine, one Loop level apart, comma-separated; the "
                  "last is the reference")
      ->required();
  cmd->add_option("--seconds", a->seconds, "script length (the press/slide script time-scaled), s")
      ->check(CLI::Range(0.2, 120.0))
      ->capture_default_str();
  cmd->add_option("--leafs", a->leafs, "leaf sizes to time on the finest level")->capture_default_str();
  cmd->add_option("--rates", a->rates, "collision rate caps, Hz (1000 = every tick)")->capture_default_str();
  cmd->add_option("--interps", a->interps, "interpolation methods")->capture_default_str();
  cmd->add_option("--samples", a->samples, "in-contact poses timed per latency figure")->capture_default_str();
  cmd->add_option("--csv", a->csv, "append one row per configuration");
  cmd->add_option("--trace-csv", a->trace_csv,
                  "write per-tick force magnitudes of the reference and a few configurations");
  cmd->callback([a] {
    geom::ContactConfig contact = geom::DefaultContactConfig();
    contact.model = geom::parse_contact_model(a->contact).value();
    const std::uint32_t default_leaf = geom::DefaultTreeConfig().leaf_faces;
    const Body probe = load_body(a->probe, default_leaf);
    std::vector<std::string> paths;
    {
      std::stringstream ss(a->levels);
      std::string tok;
      while (std::getline(ss, tok, ',')) paths.push_back(tok);
    }
    if (paths.empty()) die("trade", "--levels: no mesh");
    std::vector<LevelRun> lv(paths.size());
    for (std::size_t l = 0; l < paths.size(); ++l) {
      lv[l].body = load_body(paths[l], default_leaf);
      lv[l].depth_below_finest = int(paths.size() - 1 - l);
    }
    for (std::size_t l = 0; l + 1 < lv.size(); ++l)
      if (lv[l].body.mesh.num_faces() * 4 != lv[l + 1].body.mesh.num_faces())
        die("trade", paths[l + 1] + " is not one Loop level above " + paths[l] + " (face count is not 4x)");
    LevelRun& fine = lv.back();
    const rt::Trajectory script = press_slide_script(probe.mesh, fine.body.mesh, a->seconds);
    const std::size_t ticks = std::size_t(std::llround(a->seconds * 1000)) + 1;
    std::vector<geom::Pose> poses(ticks);
    for (std::size_t i = 0; i < ticks; ++i) poses[i] = script.at(double(i) * 1e-3);

    // Exact pairs at every tick, every level.
    const auto w0 = std::chrono::steady_clock::now();
    for (LevelRun& L : lv) {
      geom::CollideScratch sc;
      geom::CollideResult r;
      geom::CollideConfig opt;
      opt.sort_pairs = true;
      L.pairs.resize(ticks);
      L.objfaces.resize(ticks);
      for (std::size_t i = 0; i < ticks; ++i) {
        geom::collide(probe.mesh, probe.tree, L.body.mesh, L.body.tree, poses[i], opt, sc, r);
        L.pairs[i] = r.pairs;
        auto& f = L.objfaces[i];
        for (const geom::FacePair& p : r.pairs) f.push_back(p.object);
        std::sort(f.begin(), f.end());
        f.erase(std::unique(f.begin(), f.end()), f.end());
      }
      L.memory = mesh_bytes(probe.mesh) + probe.tree.bytes() + mesh_bytes(L.body.mesh) + L.body.tree.bytes();
    }
    // Sampled in-contact ticks (of the finest level) for the latency figures.
    std::vector<std::size_t> in_contact, sample;
    for (std::size_t i = 0; i < ticks; ++i)
      if (!fine.pairs[i].empty()) in_contact.push_back(i);
    if (in_contact.empty()) die("trade", "the script never touches " + paths.back());
    const std::size_t n = std::min<std::size_t>(std::size_t(std::max(1, a->samples)), in_contact.size());
    for (std::size_t j = 0; j < n; ++j) sample.push_back(in_contact[j * in_contact.size() / n]);
    for (LevelRun& L : lv) L.latency_us = time_collide(probe, L.body, poses, sample, nullptr);
    std::fprintf(stderr, "trade: %zu ticks (%zu in contact) on %zu levels in %.1f s\n", ticks, in_contact.size(),
                 lv.size(), std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count());

    const Trace ref = simulate(contact, probe, fine, poses, 1, rt::InterpMode::hold, true, &fine);
    double ref_rms = 0;
    for (const auto& f : ref.force) ref_rms += f.squaredNorm();
    ref_rms = std::sqrt(ref_rms / double(ticks));

    const std::string header =
        "table,knob,config,level,object_faces,leaf_faces,rate_hz,ticks_per_round,interp,query_us,cost_us_per_tick,"
        "memory_mb,force_rms_err_N,force_max_err_N,force_mag_rms_err_N,ref_force_rms_N,contact_recall,exact";
    struct Row {
      std::string knob, config, level, interp;
      std::size_t faces;
      unsigned leaf;
      double rate;
      int k;
      double query_us, cost, mem_mb, rms, max, mag_rms, recall;
      bool exact;
    };
    std::vector<Row> rows;
    // Vector error (direction and magnitude), and the magnitude alone (| |F| - |F_ref| |: what PD
    // interpolation can fix; direction jumps of the nearest-face FD are outside its reach).
    auto err = [&](const Trace& t, double& rms, double& mx, double& mag) {
      rms = mx = mag = 0;
      for (std::size_t i = 0; i < ticks; ++i) {
        const double e = (t.force[i] - ref.force[i]).norm();
        const double m = t.force[i].norm() - ref.force[i].norm();
        rms += e * e;
        mag += m * m;
        mx = std::max(mx, e);
      }
      rms = std::sqrt(rms / double(ticks));
      mag = std::sqrt(mag / double(ticks));
    };
    const std::vector<int> rates = parse_int_list(a->rates, "--rates");
    std::vector<rt::InterpMode> modes;
    {
      std::stringstream ss(a->interps);
      std::string tok;
      while (std::getline(ss, tok, ',')) {
        auto m = rt::parse_interp_mode(tok);
        if (!m) die("trade", m.error());
        modes.push_back(m.value());
      }
    }
    std::vector<std::pair<std::string, Trace>> traces;  // for --trace-csv
    auto run_config = [&](const std::string& knob, std::size_t l, int rate, rt::InterpMode mode) {
      const int k = std::max(1, int(std::lround(1000.0 / rate)));
      const Trace t = simulate(contact, probe, lv[l], poses, k, mode, false, &fine);
      Row r{knob,
            "",
            stem(paths[l]),
            rt::to_string(mode),
            lv[l].body.mesh.num_faces(),
            default_leaf,
            1000.0 / k,
            k,
            lv[l].latency_us,
            lv[l].latency_us / k,
            double(lv[l].memory) / 1048576.0,
            0,
            0,
            0,
            t.recall,
            true};
      err(t, r.rms, r.max, r.mag_rms);
      char name[160];
      std::snprintf(name, sizeof name, "%s leaf%u %.0fHz %s", r.level.c_str(), r.leaf, r.rate, r.interp.c_str());
      r.config = name;
      rows.push_back(r);
      traces.emplace_back(name, t);
    };
    const std::size_t fi = lv.size() - 1;
    // Mesh level at full rate with hold (no interpolation lag: the level's own error); rate cap x
    // interpolation on the finest level.
    for (std::size_t l = 0; l < lv.size(); ++l) run_config("level", l, 1000, rt::InterpMode::hold);
    for (int rate : rates)
      for (rt::InterpMode m : modes) run_config("rate_interp", fi, rate, m);
    // Leaf size: cost only (exactness checked on the sampled poses against the default leaf).
    std::vector<std::vector<geom::FacePair>> base_pairs;
    for (std::size_t i : sample) base_pairs.push_back(fine.pairs[i]);
    const Row base = rows[fi];  // finest, 1000 Hz, hold
    for (int leaf : parse_int_list(a->leafs, "--leafs")) {
      Body p = load_body(a->probe, std::uint32_t(leaf));
      Body o = load_body(paths.back(), std::uint32_t(leaf));
      std::vector<std::vector<geom::FacePair>> got;
      const double us = time_collide(p, o, poses, sample, &got);
      Row r = base;
      r.knob = "leaf";
      r.leaf = unsigned(leaf);
      r.query_us = us;
      r.cost = us;
      r.mem_mb = double(mesh_bytes(p.mesh) + p.tree.bytes() + mesh_bytes(o.mesh) + o.tree.bytes()) / 1048576.0;
      r.exact = got == base_pairs;
      char name[160];
      std::snprintf(name, sizeof name, "%s leaf%d 1000Hz hold", r.level.c_str(), leaf);
      r.config = name;
      rows.push_back(r);
    }
    std::printf("reference: %s exact every tick, hold, no delay; %zu ticks, RMS |F| %.3f N\n",
                stem(paths.back()).c_str(), ticks, ref_rms);
    std::printf("%-12s %-34s %9s %10s %8s %10s %10s %10s %8s %5s\n", "knob", "config", "query_us", "us/tick", "mem_MB",
                "rms_err_N", "max_err_N", "|F|rms_err", "recall", "exact");
    for (const Row& r : rows) {
      std::printf("%-12s %-34s %9.1f %10.2f %8.1f %10.4f %10.4f %10.4f %8.4f %5s\n", r.knob.c_str(), r.config.c_str(),
                  r.query_us, r.cost, r.mem_mb, r.rms, r.max, r.mag_rms, r.recall, r.exact ? "yes" : "NO");
      char buf[512];
      std::snprintf(buf, sizeof buf, "trade,%s,%s,%s,%zu,%u,%.2f,%d,%s,%.2f,%.3f,%.2f,%.5f,%.5f,%.5f,%.5f,%.5f,%d",
                    r.knob.c_str(), r.config.c_str(), r.level.c_str(), r.faces, r.leaf, r.rate, r.k, r.interp.c_str(),
                    r.query_us, r.cost, r.mem_mb, r.rms, r.max, r.mag_rms, ref_rms, r.recall, r.exact ? 1 : 0);
      append_csv(a->csv, header, buf);
    }
    if (!a->trace_csv.empty()) {
      std::FILE* f = std::fopen(a->trace_csv.c_str(), "w");
      if (!f) die("trade", a->trace_csv + ": cannot write");
      std::fprintf(f, "t_s,reference");
      for (const auto& [name, t] : traces) std::fprintf(f, ",%s", name.c_str());
      std::fprintf(f, "\n");
      for (std::size_t i = 0; i < ticks; ++i) {
        std::fprintf(f, "%.3f,%.5f", double(i) * 1e-3, ref.force[i].norm());
        for (const auto& [name, t] : traces) std::fprintf(f, ",%.5f", t.force[i].norm());
        std::fprintf(f, "\n");
      }
      std::fclose(f);
    }
  });
}

}  // namespace st::bench
