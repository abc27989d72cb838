// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench slides: the coherent collider (geom::CoherentCollider) against collide() along
// haptic motion. From each pose of a pose file the probe slides along the touched surface and
// turns about the contact, a fixed step per round, forth and back (a triangle wave); a jerk series
// slides at 0.01 mm and jumps 1 mm + 1° in one round half-way. Every round is timed on three
// paths: "today" (collide() with every candidate through the exact test, the path before the
// float filter), the filter (collide()'s default) and the coherent collider, each path running the
// whole series in a pass of its own; each series is run --reps times (the collider reset each
// time, the passes' order rotating) and a round's time is its median over the reps.
// The pair sets of the coherent collider and of collide() are compared on every round. With
// --withdraw, a series pulls the probe out along the contact's normal, and the rounds after the
// contact ends are reported apart (what the front of a past contact costs). With --follow, each
// round's pose is also moved along the contact's normal so that the probe stays as deep in the
// object as at the start (a hand kept on a curved surface; a straight slide leaves it or digs in).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iterator>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "bench.hpp"
#include "bench_json.hpp"
#include "bench_tables_common.hpp"
#include <spheretouch/geom/coherent.hpp>
#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/simd.hpp>
#include <spheretouch/geom/sphere_tree.hpp>

namespace st::bench {
namespace {

using geom::Mesh;
using geom::Pose;
using geom::Vec3;

constexpr double kPi = 3.14159265358979323846;

/// The motion of one series: from `start`, a slide of `step_mm` along `dir` and a turn of
/// `step_deg` about `axis` through `pivot` per round, forth for `half` rounds then back; a jerk
/// of 1 mm + 1° added from round `jerk_at` on (never when jerk_at < 0). `withdraw`: `step_mm`
/// a round along `normal`, out of the object, and no turn.
struct Series {
  Pose start;
  Vec3 pivot, dir, axis, normal;
  double step_mm = 0, step_deg = 0;
  int half = 100, jerk_at = -1;
  bool withdraw = false;

  Pose at(int k) const {
    if (withdraw) {
      Pose p = start;
      p.translation() += k * step_mm * normal;
      return p;
    }
    const int period = 2 * half;
    const int phase = k % period;
    const double s = phase <= half ? phase : period - phase;  // forth, then back
    double along = s * step_mm, turn = s * step_deg;
    if (jerk_at >= 0 && k >= jerk_at) along += 1.0, turn += 1.0;
    Pose p = Pose::Identity();
    p.linear() = Eigen::AngleAxisd(turn * kPi / 180, axis).toRotationMatrix();
    p.translation() = pivot - p.linear() * pivot + along * dir;
    return p * start;
  }
};

/// Pivot, slide direction and turn axis at a pose: the contact's centre (mean of the touched
/// object faces' centroids), a direction in the touched surface, and an axis between its normal
/// and that direction's perpendicular (a turn that twists and rolls).
bool series_at(const Mesh& object, const std::vector<geom::FacePair>& pairs, Series& s) {
  if (pairs.empty()) return false;
  Vec3 c = Vec3::Zero(), n = Vec3::Zero();
  for (const geom::FacePair& fp : pairs) {
    const auto& t = object.faces[fp.object];
    const Vec3 a = object.vertex(t[0]), b = object.vertex(t[1]), d = object.vertex(t[2]);
    c += (a + b + d) / 3;
    n += (b - a).cross(d - a);
  }
  c /= double(pairs.size());
  if (n.norm() == 0) n = Vec3::UnitZ();
  n.normalize();
  Vec3 dir = n.cross(Vec3::UnitX());
  if (dir.norm() < 0.1) dir = n.cross(Vec3::UnitY());
  dir.normalize();
  s.pivot = c;
  s.normal = n;
  s.dir = dir;
  s.axis = (n + n.cross(dir)).normalized();
  return true;
}

/// How far along `n` (out of the object) the probe at `p` must move so that it no longer overlaps
/// the object: an offset with pairs and one without, found by doubling from 0.5 mm, then bisected
/// to `tol` mm (the offset returned is the one without pairs). Nothing when no offset within
/// `reach` mm has the other answer (a probe wrapped round the object, or far from it).
std::optional<double> clear_offset(const Mesh& probe, const geom::SphereTree& pt, const Mesh& object,
                                   const geom::SphereTree& ot, const Pose& p, const Vec3& n, double reach, double tol,
                                   geom::CollideScratch& sc, geom::CollideResult& r) {
  auto touches = [&](double h) {
    Pose q = p;
    q.translation() += h * n;
    geom::collide(probe, pt, object, ot, q, {}, sc, r);
    return !r.pairs.empty();
  };
  double in = 0, out = 0;  // an offset with pairs, one without
  const bool at0 = touches(0);
  for (double h = 0.5;; h *= 2) {
    if (h > reach) return std::nullopt;
    if (touches(at0 ? h : -h) != at0) {
      (at0 ? out : in) = at0 ? h : -h;
      break;
    }
    (at0 ? in : out) = at0 ? h : -h;
  }
  while (std::abs(out - in) > tol) {
    const double mid = 0.5 * (in + out);
    (touches(mid) ? in : out) = mid;
  }
  return out;
}

/// The poses of a series kept on the surface (--follow): each round's pose moved along the start's
/// normal by the change of clear_offset() since the start, so the probe is as deep as it started.
/// A round whose offset cannot be found keeps the correction of the round before.
std::vector<Pose> followed(const Series& s, int rounds, const Mesh& probe, const geom::SphereTree& pt,
                           const Mesh& object, const geom::SphereTree& ot) {
  geom::CollideScratch sc;
  geom::CollideResult r;
  constexpr double kReach = 64, kTol = 1e-5;  // mm
  const std::optional<double> d0 = clear_offset(probe, pt, object, ot, s.start, s.normal, kReach, kTol, sc, r);
  std::vector<Pose> out;
  double shift = 0;
  for (int k = 0; k < rounds; ++k) {
    Pose p = s.at(k);
    if (d0) {
      if (const auto d = clear_offset(probe, pt, object, ot, p, s.normal, kReach, kTol, sc, r)) shift = *d - *d0;
      p.translation() += shift * s.normal;
    }
    out.push_back(p);
  }
  return out;
}

double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / double(v.size());
}

/// One series' figures.
struct SeriesRow {
  std::string name;
  std::uint32_t contacts0 = 0;
  double step_mm = 0, step_deg = 0;
  bool jerk = false, withdraw = false, follow = false;
  int rounds = 0;
  int out_rounds = 0;                                   // rounds without contact
  double out_today_us = 0, out_coherent_us = 0;         // ... their mean per round
  double today_us = 0, filter_us = 0, coherent_us = 0;  // mean per round
  double ratio_mean = 0, ratio_p90 = 0, ratio_max = 0;  // coherent / today, per round
  int ratio_max_round = 0;
  double vs_filter_mean = 0, vs_filter_p90 = 0, vs_filter_max = 0;  // coherent / filter
  double filter_ratio_mean = 0;                                     // filter / today
  double rebuild_ratio = 0;  // jerk series: the jump's round (a rebuild), coherent / today
  double max_ratio_except_rebuild = 0;
  int max_except_rebuild_round = 0;  // ... its round
  std::size_t mismatched_rounds = 0;
  geom::CoherentStats stats;
  std::size_t bytes = 0;
};

double us_since(std::chrono::steady_clock::time_point t0) {
  return 1e6 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

void add_slides(CLI::App& app) {
  struct Args {
    std::string probe, object, poses, steps = "0.001,0.01,0.05,0.1", isa;
    int rounds = 200, reps = 5;
    double turn = 0.01;
    geom::CoherentConfig coherent;
    bool jerk = true, json = false, only_coherent = false, follow = false;
    double withdraw = 0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "slides",
      "The coherent collider against collide() along slides from each pose of a pose file (per-round ratios)");
  cmd->add_option("--probe", a->probe, "probe mesh (the hand)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--object", a->object, "object mesh")->required()->check(CLI::ExistingFile);
  cmd->add_option("--poses", a->poses, "pose file: the start of the series (16 numbers a line)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--steps", a->steps, "slide per round, mm (one series each)")->capture_default_str();
  cmd->add_option("--turn", a->turn, "turn per round, degrees (every series)")->capture_default_str();
  cmd->add_option("--rounds", a->rounds, "rounds per series (forth half of them, back the other)")
      ->check(CLI::Range(4, 100000))
      ->capture_default_str();
  cmd->add_option("--reps", a->reps, "runs of each series; a round's time is its median over them")
      ->check(CLI::Range(1, 101))
      ->capture_default_str();
  cmd->add_option("--jerk", a->jerk, "also a 0.01 mm series with a 1 mm + 1° jump half-way")->capture_default_str();
  cmd->add_option("--withdraw", a->withdraw,
                  "also a series that pulls the probe out along the contact's normal this many mm a round "
                  "(0: none); the rounds without contact are reported apart")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  cmd->add_flag("--follow", a->follow,
                "keep the slides on the surface: each round's pose also moves along the contact's normal so "
                "that the probe is as deep as at the start (bisected, before any timing)");
  cmd->add_option("--reach", a->coherent.reach, "the coherent collider's reach δ, mm (0: adapted to the motion)")
      ->capture_default_str();
  cmd->add_option("--max-step", a->coherent.max_step,
                  "motion per round above which the coherent collider runs collide(), mm (0: its default)")
      ->capture_default_str();
  cmd->add_option("--isa", a->isa, "run the SIMD kernels on this instruction set (default: the best the CPU has)");
  cmd->add_flag("--json", a->json, "print one JSON object instead of the table");
  cmd->add_flag("--only-coherent", a->only_coherent,
                "run the coherent collider alone, untimed and unchecked (to profile it with perf)");
  cmd->callback([a] {
    use_isa(a->isa);
    const Mesh probe = load_mesh_or_exit(a->probe), object = load_mesh_or_exit(a->object);
    const geom::SphereTree pt = geom::SphereTree::build(probe, {}).value();
    const geom::SphereTree ot = geom::SphereTree::build(object, {}).value();
    auto lines = geom::read_pose_lines(a->poses);
    if (!lines) {
      std::fprintf(stderr, "%s\n", lines.error().c_str());
      throw CLI::RuntimeError(2);
    }
    const std::vector<double> steps = parse_positive_list(a->steps, "--steps");

    // Each path has its own scratch, as each would in a collision thread of its own (the coherent
    // collider holds one), and runs each series in a pass of its own (below).
    geom::CollideScratch sc, sc_today, sc_filter;
    geom::CollideResult r_today, r_filter, r_coh, sorted_plain;
    geom::CollideConfig today;
    today.tri_filter = false;
    const geom::CollideConfig filter;
    geom::CollideConfig sorted;
    sorted.sort_pairs = true;
    std::vector<SeriesRow> rows;
    int done = 0;
    const int total = int(lines.value().size()) * (int(steps.size()) + (a->jerk ? 1 : 0) + (a->withdraw > 0 ? 1 : 0));
    for (const geom::PoseLine& line : lines.value()) {
      geom::collide(probe, pt, object, ot, line.pose, sorted, sc, sorted_plain);
      Series base;
      base.start = line.pose;
      base.half = a->rounds / 2;
      if (!series_at(object, sorted_plain.pairs, base)) continue;
      const std::uint32_t contacts0 = sorted_plain.contacts();
      std::vector<Series> series;
      for (double st : steps) {
        Series s = base;
        s.step_mm = st, s.step_deg = a->turn;
        series.push_back(s);
      }
      if (a->jerk) {
        Series s = base;
        s.step_mm = 0.01, s.step_deg = a->turn, s.jerk_at = a->rounds / 2;
        series.push_back(s);
      }
      if (a->withdraw > 0) {
        Series s = base;
        s.step_mm = a->withdraw, s.withdraw = true;
        series.push_back(s);
      }
      for (const Series& s : series) {
        std::vector<Pose> poses;  // every round's, computed before the timing
        if (a->follow && !s.withdraw)
          poses = followed(s, a->rounds, probe, pt, object, ot);
        else
          for (int k = 0; k < a->rounds; ++k) poses.push_back(s.at(k));
        SeriesRow row;
        row.contacts0 = contacts0;
        row.step_mm = s.step_mm, row.step_deg = s.step_deg, row.jerk = s.jerk_at >= 0, row.rounds = a->rounds;
        row.withdraw = s.withdraw;
        row.follow = a->follow && !s.withdraw;
        std::vector<char> in_contact(a->rounds, 0);
        std::vector<std::vector<double>> t_today(a->rounds), t_filter(a->rounds), t_coh(a->rounds);
        geom::CoherentConfig ccfg = a->coherent;
        if (a->only_coherent) ccfg.arbitrate = false;
        geom::CoherentCollider coh(ccfg);
        // Each path runs the whole series in a pass of its own, as it would in a collision thread:
        // round after round, its own last round in cache. (Run back to back on each pose, a path
        // found the object's faces and boxes the one before it had just read: the third of three
        // measured 6-12 % faster than the first on the same code.) The passes' order rotates with
        // the repeat, so a drift of the machine's speed falls on each path alike.
        std::vector<std::vector<geom::FacePair>> coh_pairs(a->rounds);  // the first repeat's, sorted
        std::vector<std::uint32_t> coh_contacts(a->rounds, 0);
        for (int rep = 0; rep < a->reps; ++rep) {
          const int passes = a->only_coherent ? 1 : 3;
          for (int pass = 0; pass < passes; ++pass) {
            const int path = a->only_coherent ? 2 : (pass + rep) % 3;
            if (path == 2) coh.reset(), coh.reset_stats();
            for (int k = 0; k < a->rounds; ++k) {
              const Pose& pose = poses[k];
              const auto t0 = std::chrono::steady_clock::now();
              if (path == 0) {
                geom::collide(probe, pt, object, ot, pose, today, sc_today, r_today);
                t_today[k].push_back(us_since(t0));
              } else if (path == 1) {
                geom::collide(probe, pt, object, ot, pose, filter, sc_filter, r_filter);
                t_filter[k].push_back(us_since(t0));
              } else {
                coh.collide(probe, pt, object, ot, pose, filter, r_coh);
                t_coh[k].push_back(us_since(t0));
                if (rep == 0 && !a->only_coherent) {  // kept for the comparison below (untimed)
                  coh_pairs[k] = r_coh.pairs;
                  std::sort(coh_pairs[k].begin(), coh_pairs[k].end());
                  coh_contacts[k] = r_coh.contacts();
                }
              }
            }
          }
        }
        // The pair sets, every round: the coherent collider's against collide()'s.
        for (int k = 0; k < a->rounds && !a->only_coherent; ++k) {
          geom::collide(probe, pt, object, ot, poses[k], sorted, sc, sorted_plain);
          in_contact[k] = !sorted_plain.pairs.empty();
          const auto& pairs = coh_pairs[k];
          if (pairs == sorted_plain.pairs && coh_contacts[k] == sorted_plain.contacts()) continue;
          if (row.mismatched_rounds == 0) {  // the first disagreement of the series, for the record
            std::vector<geom::FacePair> only_c, only_p;
            std::set_difference(pairs.begin(), pairs.end(), sorted_plain.pairs.begin(), sorted_plain.pairs.end(),
                                std::back_inserter(only_c));
            std::set_difference(sorted_plain.pairs.begin(), sorted_plain.pairs.end(), pairs.begin(), pairs.end(),
                                std::back_inserter(only_p));
            std::fprintf(stderr, "round %d: %zu vs %zu pairs, only coherent %zu, only plain %zu, dup %d\n", k,
                         pairs.size(), sorted_plain.pairs.size(), only_c.size(), only_p.size(),
                         int(std::adjacent_find(pairs.begin(), pairs.end()) != pairs.end()));
            for (std::size_t i = 0; i < std::min<std::size_t>(3, only_p.size()); ++i)
              std::fprintf(stderr, "  only plain: %u %u\n", only_p[i].probe, only_p[i].object);
            for (std::size_t i = 0; i < std::min<std::size_t>(3, only_c.size()); ++i)
              std::fprintf(stderr, "  only coherent: %u %u\n", only_c[i].probe, only_c[i].object);
          }
          ++row.mismatched_rounds;
        }
        row.stats = coh.stats();
        if (a->only_coherent) continue;
        std::vector<double> ratio, vs_filter, filter_ratio;
        double sum_today = 0, sum_filter = 0, sum_coh = 0;
        for (int k = 0; k < a->rounds; ++k) {
          const double td = percentile(t_today[k], 0.5), tf = percentile(t_filter[k], 0.5), tc = percentile(t_coh[k], 0.5);
          sum_today += td, sum_filter += tf, sum_coh += tc;
          ratio.push_back(tc / td);
          vs_filter.push_back(tc / tf);
          filter_ratio.push_back(tf / td);
        }
        row.today_us = sum_today / a->rounds, row.filter_us = sum_filter / a->rounds, row.coherent_us = sum_coh / a->rounds;
        row.ratio_mean = mean(ratio), row.ratio_p90 = percentile(ratio, 0.9);
        row.ratio_max_round = int(std::max_element(ratio.begin(), ratio.end()) - ratio.begin());
        row.ratio_max = ratio[row.ratio_max_round];
        row.vs_filter_mean = mean(vs_filter), row.vs_filter_p90 = percentile(vs_filter, 0.9);
        row.vs_filter_max = *std::max_element(vs_filter.begin(), vs_filter.end());
        row.filter_ratio_mean = mean(filter_ratio);
        // The first round builds the front (a rebuild, cold); a jerk's rebuild is the jump's round
        // (the collider rebuilds its front there rather than run collide() and rebuild after).
        const int rebuild = s.jerk_at >= 0 ? s.jerk_at : 0;
        row.rebuild_ratio = ratio[rebuild];
        for (int k = 0; k < a->rounds; ++k)
          if (k != rebuild && k != 0 && ratio[k] > row.max_ratio_except_rebuild)
            row.max_ratio_except_rebuild = ratio[k], row.max_except_rebuild_round = k;
        for (int k = 0; k < a->rounds; ++k)
          if (!in_contact[k]) {
            ++row.out_rounds;
            row.out_today_us += percentile(t_today[k], 0.5), row.out_coherent_us += percentile(t_coh[k], 0.5);
          }
        if (row.out_rounds > 0) row.out_today_us /= row.out_rounds, row.out_coherent_us /= row.out_rounds;
        char name[96];
        if (row.withdraw)
          std::snprintf(name, sizeof name, "withdraw %.3g mm/round", s.step_mm);
        else
          std::snprintf(name, sizeof name, "%s%.3g mm + %.3g°/round%s", row.jerk ? "jerk at " : "", s.step_mm,
                        s.step_deg, row.follow ? ", followed" : "");
        row.name = name;
        rows.push_back(row);
        ++done;
        if (!a->json) std::fprintf(stderr, "  [%d/%d] %u contacts, %s\n", done, total, contacts0, name);
      }
    }

    if (a->json) {
      Json out = Json::array();
      for (const SeriesRow& w : rows)
        out.push_back({{"contacts", w.contacts0},
                       {"step_mm", w.step_mm},
                       {"step_deg", w.step_deg},
                       {"jerk", w.jerk},
                       {"withdraw", w.withdraw},
                       {"follow", w.follow},
                       {"out_rounds", w.out_rounds},
                       {"out_today_us", round_to(w.out_today_us, 2)},
                       {"out_coherent_us", round_to(w.out_coherent_us, 2)},
                       {"rounds", w.rounds},
                       {"today_us", round_to(w.today_us, 2)},
                       {"filter_us", round_to(w.filter_us, 2)},
                       {"coherent_us", round_to(w.coherent_us, 2)},
                       {"ratio_mean", round_to(w.ratio_mean, 4)},
                       {"ratio_p90", round_to(w.ratio_p90, 4)},
                       {"ratio_max", round_to(w.ratio_max, 4)},
                       {"ratio_max_round", w.ratio_max_round},
                       {"max_ratio_except_rebuild", round_to(w.max_ratio_except_rebuild, 4)},
                       {"max_except_rebuild_round", w.max_except_rebuild_round},
                       {"rebuild_ratio", round_to(w.rebuild_ratio, 4)},
                       {"vs_filter_mean", round_to(w.vs_filter_mean, 4)},
                       {"vs_filter_p90", round_to(w.vs_filter_p90, 4)},
                       {"vs_filter_max", round_to(w.vs_filter_max, 4)},
                       {"filter_ratio_mean", round_to(w.filter_ratio_mean, 4)},
                       {"mismatched_rounds", w.mismatched_rounds},
                       {"plain_rounds", w.stats.plain_rounds},
                       {"rebuilds", w.stats.rebuilds},
                       {"refreshes", w.stats.refreshes},
                       {"expansions", w.stats.expansions},
                       {"reused", w.stats.reused},
                       {"retested", w.stats.retested},
                       {"overflows", w.stats.overflows},
                       {"front_entries", w.stats.entries},
                       {"candidates", w.stats.candidates},
                       {"peak_pool_bytes", w.stats.peak_bytes},
                       {"bytes", w.bytes}});
      print_json({{"probe", a->probe},
                  {"object", a->object},
                  {"probe_faces", probe.num_faces()},
                  {"object_faces", object.num_faces()},
                  {"rounds", a->rounds},
                  {"reps", a->reps},
                  {"isa", geom::simd::isa_name(geom::simd::active_isa())},
                  {"series", std::move(out)}});
      return;
    }
    std::printf("%s x %s, %d rounds per series, median of %d reps per round, SIMD %s\n", a->probe.c_str(),
                a->object.c_str(), a->rounds, a->reps, geom::simd::isa_name(geom::simd::active_isa()));
    std::printf("%8s %-42s %9s %9s %9s %7s %7s %7s %9s %9s %8s %8s %8s %9s %5s\n", "contacts", "series", "today_us",
                "filter_us", "coh_us", "mean", "p90", "max", "max_ex_rb", "rebuild", "vs_filt", "refresh", "no_pairs",
                "pool_MB", "same");
    for (const SeriesRow& w : rows)
      std::printf("%8u %-42s %9.1f %9.1f %9.1f %7.3f %7.3f %7.3f %9.3f %9.3f %8.3f %8llu %8d %9.2f %5s\n", w.contacts0,
                  w.name.c_str(), w.today_us, w.filter_us, w.coherent_us, w.ratio_mean, w.ratio_p90, w.ratio_max,
                  w.max_ratio_except_rebuild, w.rebuild_ratio, w.vs_filter_mean,
                  static_cast<unsigned long long>(w.stats.refreshes), w.out_rounds, double(w.stats.peak_bytes) / 1e6,
                  w.mismatched_rounds == 0 ? "yes" : "NO");
    for (const SeriesRow& w : rows)
      if (w.withdraw)
        std::printf("%u contacts, %s: %d of %d rounds without contact, today %.1f µs, coherent %.1f µs a round\n",
                    w.contacts0, w.name.c_str(), w.out_rounds, w.rounds, w.out_today_us, w.out_coherent_us);
  });
}

}  // namespace st::bench
