// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// CoherentCollider: collide() for a probe that moves a little between rounds (the haptic loop:
/// 0.01–0.1 mm a millisecond). It returns exactly collide()'s pair set, and skips the tests whose
/// outcome a certificate proves unchanged since the pose it was made at.
//
// What it keeps (the front of the last traversal, each entry with the pose it was proved at):
//  * a group of sphere pairs found apart: the children of one node (or the pair itself) against
//    the other node, with their smallest gap g. Valid while the probe node has moved less than g.
//  * a leaf pair, with its candidate triangle pairs gathered with face boxes widened by the
//    reach δ: every other face pair of the leaf pair is more than δ apart. Each candidate keeps
//    its answer and its margin (the separation, or the depth of the origin inside P − O, proved
//    by the certified float filter, or 0 when the exact test decided). Valid while the probe leaf
//    has moved less than δ; a candidate's answer holds while the leaf moved less than its margin,
//    else it is tested again at this pose. The candidates' margins are measured from one pose of
//    their entry, its anchor A, so a visit computes one bound B(A, now) for all of them. A visit
//    that tests some again moves the anchor to this pose: the others keep their margin less
//    B(A, now) (a point's motion from A to a later pose is at most B(A, now) plus its motion from
//    now), which loses nothing while the motion goes one way; a visit that tests none keeps A,
//    so jitter uses nothing up.
// "Moved" is a bound on |apply(T, v) - apply(T_i, v)| over the node's sphere, T_i the pose the
// certificate was made at (never a sum of steps: jitter back and forth uses no margin up):
// |(R - R_i) c + (t - t_i)| + ||R - R_i||_F r, widened for the rounding of both apply()s.
// A shortcut for the groups: the probe's path, the whole probe's bounds from each cached pose to
// the next summed as the rounds go (each rounded up to a multiple of a power of two, so that the
// sums are exact). A group whose node was found to have moved m < g since its pose at a round
// where the path was L stays apart while the path is below its level L + g - m, rounded down (a
// point's motion from T_i to now is at most its motion to that round plus its path since): one
// comparison a round, on an array of the groups' levels; only past its level is a group's motion
// bounded from T_i again, which sets a new level. The sum only makes a round's check cheaper,
// never a certificate shorter: jitter still uses none up.
// Why that is enough: a probe point moves by at most that bound, so a gap larger than it stays
// open, and the support function of P − O changes by at most it in any direction, so a depth
// larger than it keeps the origin inside (coherent_traversal.inl proves the margins).
// A leaf pair's certificate is refreshed before it runs out, at a fraction of δ that differs
// between leaf pairs (staggered), so refreshes spread over rounds instead of falling on one.
// What bounds a round's cost: a rebuild descends only the sphere pairs that meet (as collide()
// does; those apart by less than δ become groups with their gap, expanded a few at a time by the
// motion of the next rounds) and builds no leaf pair, so it costs about what collide() does; leaf
// pairs are (re)built within a budget per round (2 % of the front's after a rebuild, growing to
// 25 %; a pair whose face boxes gather no candidate counts a quarter), the others answered by
// collide()'s own leaf stage meanwhile; a round whose probe (its part in contact) moved more than
// max_step since the last one runs collide() and drops the cache, unless rounds have been answered
// from the front since it was built (a jerk out of slow motion: the front is rebuilt at once, so a
// jerk costs one rebuild; fast motion, one rebuild, then plain rounds); a probe clear of the
// object (its root sphere apart from every object root) costs one sphere test per root, as in
// collide(), and drops the front; the front is walked again from the roots when it has doubled
// (it only refines as the probe moves) or the contact has shrunk to a quarter or ended (a
// withdrawn probe would keep the fine front of its contact; ended, the walk is a rebuild: no leaf
// pair is worth keeping); and,
// with `arbitrate`, the collider times itself against collide() and gives way to it where the
// bookkeeping costs more than it saves.
// Other trees or other object roots (a worker asked to skip other blocks this round) start a new
// front only when a second round in a row asks for them: a setup met once is answered by
// collide() and the front kept for the one it was built for, so rounds that alternate (a client
// that takes a worker's busiest block some rounds and not others) cost no rebuild each.
#pragma once
#include <spheretouch/abi.hpp>
#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <spheretouch/geom/collide.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// The coherent collider's knobs (every distance in the meshes' units).
struct CoherentConfig {
  /// Reach δ of a leaf pair's candidates (face pairs farther apart than δ are not kept).
  /// 0 = adapt to the motion: 8 steps of the recent motion per round, within
  /// [leaf radius / 16, leaf radius / 8] (the probe tree's mean leaf radius; a smaller δ at slow
  /// motion made more refreshes than its smaller candidate sets saved).
  double reach = 0;
  /// Motion in one round (a bound over the probe's faces in contact the round before, or over the
  /// whole probe when none were) above which the round runs plain collide() and the cache is
  /// dropped. 0 = the probe tree's mean leaf radius / 64 (faster than that, certificates last too
  /// few rounds to pay for themselves).
  double max_step = 0;
  /// Bound on the cache (entries + candidates), bytes. A round that would exceed it runs plain
  /// collide(), and so do the next 64 rounds.
  std::size_t max_bytes = std::size_t(64) << 20;
  /// Time itself against collide() (a plain round every 128, the cache kept; skipped while it
  /// takes under 0.75 of collide()'s time on a contact within a factor of 2 of the one collide()
  /// was last timed on (before it has been timed: under 0.6 of the rebuild's time), up to 1,024
  /// rounds: a timed round runs cold; the other plain rounds, jumps
  /// and spells, read no clock) and give way to it
  /// for 256 rounds (doubling, up to 8192, while it keeps losing) when its rounds cost more than
  /// 0.95 of collide()'s (light contact, where collide() takes microseconds and the
  /// certificates' bookkeeping does not pay). The pairs are the same either way; false makes the
  /// choice of path depend on the motion alone (deterministic counters, for tests).
  bool arbitrate = true;
};

/// What the coherent collider did (totals since construction or reset_stats()).
struct CoherentStats {
  std::uint64_t rounds = 0;  ///< rounds answered
  /// of those, by plain collide() (a jump in the round after a rebuild or a plain round, the pool
  /// full, a mode it does not cache, other trees or object roots asked for once)
  std::uint64_t plain_rounds = 0;
  std::uint64_t rebuilds = 0;    ///< rounds that started from the roots (first round, after a drop)
  std::uint64_t reroots = 0;     ///< rounds that walked again from the roots, keeping the leaf pairs' entries
  std::uint64_t expansions = 0;  ///< groups of apart sphere pairs tested again (their gap used up)
  std::uint64_t refreshes = 0;   ///< leaf pairs due for their candidates to be gathered again
  /// leaf pairs answered by collide()'s leaf stage while their build waited for a round's budget
  std::uint64_t deferred = 0;
  std::uint64_t reused = 0;     ///< candidate answers taken from their certificate
  std::uint64_t retested = 0;   ///< candidates tested again (margin used up)
  std::uint64_t overflows = 0;  ///< rounds that found the pool over max_bytes
  std::uint64_t gave_way = 0;   ///< times its rounds cost more than collide()'s and it gave way (arbitrate)
  std::size_t entries = 0;      ///< front entries after the last round
  std::size_t candidates = 0;   ///< candidate pairs after the last round
  std::size_t peak_bytes = 0;   ///< most pool bytes held after a round
};

namespace detail {
/// One entry of the front (coherent.hpp, top): apart sphere pairs, or a leaf pair.
struct FrontEntry {
  /// group: apart while the probe's path (CoherentCollider::path_) is below this; leaf pair: the motion
  /// charged to its candidates since they were gathered, each margin stored with it added
  /// (coherent.hpp, top)
  double level = 0;
  std::uint32_t p = 0, o = 0;  ///< probe node, object node
  std::uint32_t pose = 0;      ///< round the certificate was made at
  float margin = 0;            ///< group: smallest gap; leaf pair: the reach δ its candidates were gathered with
  std::uint32_t arg = 0;       ///< group: bit k = child k is in the group; leaf pair: first candidate
  std::uint16_t count = 0;     ///< leaf pair: candidates
  std::uint8_t kind = 0;       ///< FrontKind
  std::uint8_t theta = 0;      ///< leaf pair: refreshed once it moved (768 + theta) / 1024 of δ
  std::uint32_t anchor = 0;    ///< leaf pair: the round its candidates' margins are measured from
  float c[3] = {};             ///< probe node p's sphere centre (probe-local), copied: a check reads nothing else
  float r = 0;                 ///< ... and its radius
};
/// The kinds of FrontEntry.
enum FrontKind : std::uint8_t {
  kPairApart = 0,       ///< the pair (p, o) itself is apart
  kObjectChildren = 1,  ///< the children of o in `arg` are apart from p
  kProbeChildren = 2,   ///< the children of p in `arg` are apart from o
  kLeafPair = 3,        ///< leaf pair with candidates
  kLeafPending = 4,     ///< leaf pair near, not built yet: answered by collide()'s leaf stage
  kDead = 5,            ///< a group expanded (its slot in the group store awaits compaction)
};
/// A candidate triangle pair of a leaf pair and its certificate.
struct Candidate {
  std::uint32_t slot = 0;  ///< probe slot (tree order)
  std::uint32_t face = 0;  ///< object face
  /// The answer holds while the probe leaf's motion bound since its entry's anchor is less than this.
  float margin = 0;
  std::uint8_t hit = 0;  ///< 1 when the faces intersect while the certificate holds
  std::uint8_t j = 0;    ///< the object face's place in its leaf (candidates are in (j, slot) order)
};
/// A round's change since a certificate pose (coherent_traversal.inl), kept per ring slot.
struct PoseDelta {
  Eigen::Matrix3d D;          ///< R - R_i
  Vec3 dt;                    ///< t - t_i
  double norm = 0;            ///< ||D||_F
  double rnd = 0;             ///< rounding allowance of the bound
  double whole = 0;           ///< the motion bound of the whole probe (its root sphere)
  std::uint64_t key = ~0ull;  ///< (round << 32) | pose it was computed for
};
/// A pose certificates were made at.
struct CertPose {
  RelTransform rt;
  double mag = 0;             ///< magnitude of the coordinates (for the rounding allowance)
  std::uint32_t round = ~0u;  ///< the round it belongs to (a ring slot holds one of many)
};
}  // namespace detail

/// collide() with certificates carried between rounds (coherent.hpp, top). One per (probe, object)
/// pair and per caller thread, like CollideScratch; not thread-safe.
class CoherentCollider {
 public:
  /// A collider with these knobs; its caches are sized on the first round.
  explicit CoherentCollider(const CoherentConfig& config = {}) : config_(config) {}

  /// The pair set collide() gives for the same arguments (same pairs, same counts; the order may
  /// differ unless options.sort_pairs). Approximate modes (stop_layer != kExact) and a round of
  /// tri_filter = false run collide() itself. A round stopped by max_pairs or max_work drops the cache.
  void collide(const Mesh& probe, const SphereTree& probe_tree, const Mesh& object, const SphereTree& object_tree,
               const Pose& pose, const CollideConfig& options, CollideResult& result);
  /// Forgets every certificate: the next round starts from the roots.
  void reset();
  /// Zeroes the counters.
  void reset_stats() { stats_ = {}; }
  const CoherentStats& stats() const { return stats_; }     ///< what it did
  const CoherentConfig& config() const { return config_; }  ///< its knobs
  /// Heap bytes held: the cache (at most config().max_bytes, plus one round's growth) and the scratch.
  std::size_t bytes() const;
  /// The reach δ the next rebuilt entries use (after the first round: resolved from config().reach).
  double reach() const { return reach_; }

 private:
  template <class Lanes>
  friend struct CoherentQuery;                       // coherent_traversal.inl: one per instruction set
  static constexpr std::uint32_t kPoses = 256;       // certificate poses kept; older entries are redone
  static constexpr std::uint32_t kRerootEvery = 64;  // rounds between walks from the roots
  static constexpr std::uint32_t kTimeEvery = 128;   // arbitrate: a plain round timed this often (unless settled())
  static constexpr std::uint32_t kPlainSpell = 256;  // arbitrate: plain rounds after giving way

  // The front was built for these trees and object roots.
  bool same_setup(const SphereTree& probe_tree, const SphereTree& object_tree, const CollideConfig& options) const;
  // Drops the front and remembers what the next is built for (the probe's leaf radius too).
  void adopt(const SphereTree& probe_tree, const SphereTree& object_tree, const CollideConfig& options);
  // A hash of the setup (trees and object roots): what a round that is not same_setup() asked for.
  static std::uint64_t setup_key(const SphereTree& probe_tree, const SphereTree& object_tree, const CollideConfig& options);
  // Forgets the front (the next cached round rebuilds from the roots).
  void drop();
  // Copies the live candidates to the front of the pool (in front order), dropping the garbage.
  void compact();
  // Bound on how far the points of the sphere (c, r) moved from pose `a` to pose `b`.
  static double moved_since(const RelTransform& a, const RelTransform& b, const Vec3& c, double r);
  // near_ from a round's pairs (a sample of their probe faces), or none.
  void note_contact(const Mesh& probe, const CollideResult& result);
  // Leaf pairs this round may build: none in a rebuild, then a share of the front's that grows
  // from 2 % to 25 % (coherent.hpp, top).
  std::uint32_t build_budget() const;
  // This round walks from the roots again (checked every kRerootEvery rounds): the front has
  // doubled since it last did, or the contact has shrunk to under a quarter of what it was then,
  // or there is none (a probe withdrawn leaves a front as fine as the contact it had, and moving
  // away only refines it: a walk from the roots makes it as coarse as the contact now, and costs
  // what collide() does, little without contact). Without contact it is a rebuild instead
  // (rebuild_due()): the walk would index and look up leaf pairs none of which is worth keeping.
  bool reroot_due() const {
    return have_front_ && ramp_ % kRerootEvery == kRerootEvery - 1 &&
           (entries() > 2 * rooted_size_ || 4 * last_pairs_ + 16 < rooted_pairs_);
  }
  // The walk from the roots due this round finds no contact to keep (reroot_due()): the front is
  // dropped and rebuilt.
  bool rebuild_due() const { return have_front_ && ramp_ % kRerootEvery == kRerootEvery - 1 && last_pairs_ == 0; }
  // The pool (what max_bytes bounds) with `leaf_entries` leaf-pair entries: those, the group
  // store (dead entries included until compacted) and the candidates.
  std::size_t pool_bytes(std::size_t leaf_entries) const {
    return (leaf_entries + groups_.size()) * sizeof(detail::FrontEntry) + glevel_.size() * sizeof(double) +
           cands_.size() * sizeof(detail::Candidate);
  }
  // Live entries of the front: leaf pairs and groups.
  std::size_t entries() const { return front_.size() + groups_.size() - dead_; }
  // The pool's figures in stats_ after a round (entries, candidates, peak bytes).
  void note_pool() {
    stats_.entries = entries();
    stats_.candidates = cands_.size();
    stats_.peak_bytes = std::max(stats_.peak_bytes, pool_bytes(front_.size()));
  }
  // Drops the dead groups once they are most of the store.
  void compact_groups();
  // δ for this round's new entries (config_.reach, or adapted to step_).
  double choose_reach() const;

  CoherentConfig config_;
  CoherentStats stats_;
  CollideScratch scratch_;
  // The front: its leaf pairs (front_, rewritten each round as next_front_) and its groups of
  // apart pairs (groups_, kept in place: a round looks at each, expands the few whose gap the
  // motion used up into new entries appended, and marks those kDead; most stay untouched).
  std::vector<detail::FrontEntry> front_, next_front_;
  std::vector<detail::FrontEntry> groups_, old_groups_;  // old_groups_: the groups a re-rooting round walks past
  std::vector<double> glevel_;  // per group of groups_: its level (+inf when dead), what a round's scan reads
  std::size_t dead_ = 0;        // kDead entries in groups_
  std::vector<detail::Candidate> cands_, next_cands_;  // leaf pairs' candidates (in place); compact()'s scratch
  std::size_t garbage_ = 0;                            // candidates of refreshed leaf pairs still in cands_
  std::vector<std::pair<std::uint64_t, std::uint32_t>> leaf_index_;  // re-rooting: (p << 32 | o, front entry)
  std::array<detail::CertPose, kPoses> poses_{};
  std::array<detail::PoseDelta, kPoses> deltas_{};  // this round's change since each kept pose (lazily)
  std::uint32_t round_ = 0;                         // rounds since reset (the current pose's id)
  std::uint32_t last_cached_ = ~0u;                 // the last round whose pose is in poses_ (~0u: none)
  // The probe's path at that round: the whole probe's motion bounds from cached pose to cached
  // pose, each rounded up to a multiple of path_quantum_ (a power of two), summed since reset or
  // the last rebase: every sum exact (coherent.hpp, top).
  double path_ = 0;
  double path_quantum_ = 0;      // 2^-40 of the probe's root radius, rounded down to a power of two
  double path_per_quantum_ = 0;  // its inverse (a power of two too: a product by it is exact)
  bool have_front_ = false;
  std::uint32_t leaf_entries_ = 0;         // leaf pairs (built or pending) in the front
  std::size_t rooted_size_ = 0;            // front entries after the last walk from the roots
  std::size_t rooted_pairs_ = 0;           // ... and the pairs of that round
  std::uint32_t ramp_ = 0;                 // rounds since the front was rebuilt (the build budget grows with it)
  std::uint32_t plain_until_ = 0;          // after an overflow or giving way: plain rounds until this round
  double plain_ns_ = 0, coherent_ns_ = 0;  // arbitrate: recent round times (moving averages)
  std::uint32_t timed_round_ = 0;          // arbitrate: the last plain round (its time is in plain_ns_)
  std::size_t timed_pairs_ = 0;            // ... and its pair count
  std::size_t last_pairs_ = 0;             // the last round's pair count
  double rebuild_ns_ = 0;                  // arbitrate: the time of the last rebuild (0: none since reset)
  std::uint32_t rebuild_round_ = 0;        // ... its round
  std::size_t rebuild_pairs_ = 0;          // ... and its pair count
  // arbitrate: no plain round need be timed now, the collider winning by a quarter at least
  // (under 0.75 of collide()'s time: far from the 0.95 where it gives way) on a contact about as
  // large as when collide() was last timed, not long ago. A timed round runs cold (1.04-1.4x a
  // plain round in a run of plain rounds), so it is spent only where the choice is in doubt.
  // Before collide() has been timed, the last rebuild stands in for it (collide()'s descent and
  // leaf stage and the front's bookkeeping: 1.13-1.3x collide()'s time on the perf poses, taken
  // at 0.8 of it), so a collider that wins from the start runs no cold timed round at 127.
  bool settled(std::uint32_t round) const {
    if (plain_ns_ > 0)
      return coherent_ns_ < 0.75 * plain_ns_ && round - timed_round_ < 8 * kTimeEvery && alike(last_pairs_, timed_pairs_);
    return rebuild_ns_ > 0 && coherent_ns_ < 0.75 * 0.8 * rebuild_ns_ && round - rebuild_round_ < 8 * kTimeEvery &&
           alike(last_pairs_, rebuild_pairs_);
  }
  // Contacts about as large (pair counts within a factor of 2, or both small).
  static bool alike(std::size_t a, std::size_t b) { return a <= 2 * b + 16 && b <= 2 * a + 16; }
  std::uint32_t coherent_rounds_ = 0;  // arbitrate: coherent rounds since it last gave way
  std::uint32_t spells_ = 0;           // arbitrate: times in a row it gave way (the spell doubles)
  // What the front was built for.
  const void* probe_key_ = nullptr;
  const void* object_key_ = nullptr;
  std::uint64_t probe_hash_ = 0, object_hash_ = 0;
  std::vector<std::uint32_t> roots_;
  bool restrict_ = false;
  // The other setup the round before asked for (setup_key(); 0: none): adopted when asked again.
  // Only decides between a rebuild and a plain round, never the pairs (a hash collision adopts).
  std::uint64_t pending_setup_ = 0;
  // Motion.
  RelTransform last_rt_{};
  bool have_last_ = false;
  double leaf_radius_ = 0;  // the probe tree's mean leaf radius
  double step_ = 0;         // recent motion per round (decaying maximum)
  struct {
    Vec3 centre{Vec3::Zero()};  // probe-local
    double radius = -1;         // < 0: none
  } near_;                      // the probe's part in contact last round, where the step is measured
  double reach_ = 0;
  double max_step_ = 0;  // config_.max_step resolved
};

}  // namespace st::geom
