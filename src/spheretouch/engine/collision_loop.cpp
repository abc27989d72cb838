// SPDX-License-Identifier: BSD-3-Clause
// Collision thread: see collision_loop.hpp.
#include <spheretouch/engine/collision_loop.hpp>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/pod.hpp>
#include <spheretouch/rt/clock.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

namespace {

/// The top level over many objects: a static tree of bounding spheres (objects are static), built
/// top-down by splitting the objects at the median of their centres along the widest axis. A
/// probe far from every object costs the root's test; one near an object, about 2·log2(n) tests.
/// Conservative: each node's sphere encloses its children's (radius rounded up by a relative
/// 1e-12), so no object the probe's sphere reaches is missed.
class ObjectTree {
 public:
  explicit ObjectTree(const std::vector<BoundingSphere>& spheres) {
    std::vector<std::uint32_t> ids(spheres.size());
    for (std::uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;
    nodes_.reserve(2 * ids.size());
    if (!ids.empty()) build(ids, 0, ids.size(), spheres);
  }
  /// Appends to `out` every object whose sphere meets `probe` (BoundingSphere::meets), in no
  /// particular order. `stack` is scratch.
  void query(const BoundingSphere& probe, std::vector<std::uint32_t>& out, std::vector<std::uint32_t>& stack) const {
    if (nodes_.empty()) return;
    stack.clear();
    stack.push_back(0);
    while (!stack.empty()) {
      const Node& n = nodes_[stack.back()];
      stack.pop_back();
      if (!n.sphere.meets(probe)) continue;
      if (n.object != UINT32_MAX) {
        out.push_back(n.object);
      } else {
        stack.push_back(n.left);
        stack.push_back(n.right);
      }
    }
  }

 private:
  struct Node {
    BoundingSphere sphere;
    std::uint32_t left = 0, right = 0;  ///< inner: the children
    std::uint32_t object = UINT32_MAX;  ///< leaf: the object
  };
  std::uint32_t build(std::vector<std::uint32_t>& ids, std::size_t lo, std::size_t hi, const std::vector<BoundingSphere>& s) {
    const auto at = std::uint32_t(nodes_.size());
    nodes_.emplace_back();
    if (hi - lo == 1) {
      nodes_[at].sphere = s[ids[lo]];
      nodes_[at].object = ids[lo];
      return at;
    }
    Eigen::AlignedBox3d box;
    for (std::size_t i = lo; i < hi; ++i) box.extend(s[ids[i]].centre);
    int axis = 0;
    box.sizes().maxCoeff(&axis);
    const std::size_t mid = (lo + hi) / 2;
    std::nth_element(ids.begin() + std::ptrdiff_t(lo), ids.begin() + std::ptrdiff_t(mid), ids.begin() + std::ptrdiff_t(hi),
                     [&](std::uint32_t a, std::uint32_t b) { return s[a].centre(axis) < s[b].centre(axis); });
    const std::uint32_t left = build(ids, lo, mid, s), right = build(ids, mid, hi, s);
    const geom::Vec3 centre = box.center();
    double radius = 0;
    for (std::size_t i = lo; i < hi; ++i)
      radius = std::max(radius, (s[ids[i]].centre - centre).norm() + s[ids[i]].radius);
    nodes_[at].sphere = {centre, radius * (1 + 1e-12)};
    nodes_[at].left = left;
    nodes_[at].right = right;
    return at;
  }
  std::vector<Node> nodes_;
};

}  // namespace

CollisionLoop::CollisionLoop(const geom::Mesh& probe, const BoundingSphere& probe_bound, std::vector<WorldObject> objects,
                             rt::TripleBuffer<rt::PoseSample>& poses, rt::TripleBuffer<geom::ContactSet>& models,
                             CollideFn collide, double rate_hz, std::size_t max_rounds, const geom::ContactConfig& contact)
    : probe_(probe),
      probe_bound_(probe_bound),
      objects_(std::move(objects)),
      poses_(poses),
      models_(models),
      collide_(std::move(collide)),
      object_stats_(objects_.size()),
      rate_hz_(rate_hz),
      max_rounds_(max_rounds) {
  ST_ASSERT(!objects_.empty(), "a world of at least one object");
  records_.reserve(max_rounds_);
  builders_.reserve(objects_.size());
  for (const WorldObject& o : objects_) {
    builders_.emplace_back(contact);
    builders_.back().prepare(probe_, *o.mesh);
  }
}

CollisionLoop::~CollisionLoop() { stop(); }

Status CollisionLoop::write_rounds_csv(const std::string& path) {
  rounds_csv_ = std::fopen(path.c_str(), "w");
  if (!rounds_csv_) return fail(path, ": cannot create the per-round trace");
  rounds_path_ = path;
  std::fputs("start_ns,end_ns,pose_seq,pairs,contacts,pd_mm,complete\n", rounds_csv_);
  return Ok{};
}

void CollisionLoop::start() {
  thread_ = std::thread([this] { run(); });
}

void CollisionLoop::stop() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
  if (rounds_csv_) {
    const bool flushed = std::fflush(rounds_csv_) == 0 && std::ferror(rounds_csv_) == 0;
    const int flush_errno = errno;
    const bool closed = std::fclose(rounds_csv_) == 0;
    if (rounds_error_.empty() && (!flushed || !closed))
      rounds_error_ = rounds_path_ + ": write failed: " + std::strerror(flushed ? errno : flush_errno);
    rounds_csv_ = nullptr;
  }
}

void CollisionLoop::run() {
  const std::size_t n = objects_.size();
  const bool single = n == 1;  // one object: never culled, its model sent every round
  // Per object: the inverse placement, whether it is placed at all (an unplaced object's model is
  // already in the world), its round's pairs, and how long a release is still sent.
  std::vector<geom::Pose> to_object(n);
  std::vector<char> placed(n), was_contact(n, 0);
  std::vector<BoundingSphere> world_bound(n);  // each object's sphere, placed
  for (std::size_t k = 0; k < n; ++k) {
    to_object[k] = objects_[k].placement.inverse();
    placed[k] = !objects_[k].placement.isApprox(geom::Pose::Identity(), 0.0);
    world_bound[k] = objects_[k].bound.moved(objects_[k].placement);
  }
  std::vector<RoundOutput> outs(n);
  std::vector<std::int64_t> linger_until(n, 0);
  // The live view's face ids: object k's offset by the faces of the objects before it.
  std::vector<std::uint32_t> face_offset(n, 0);
  for (std::size_t k = 1; k < n; ++k)
    face_offset[k] = face_offset[k - 1] + std::uint32_t(objects_[k - 1].mesh->num_faces());
  // The top level: a tree over the objects' placed bounding spheres.
  const ObjectTree tree(world_bound);
  std::vector<std::uint32_t> work, stack, active_list, next_active;
  std::vector<char> near(n, 0);
  work.reserve(n);
  active_list.reserve(n);
  next_active.reserve(n);
  // This round's models, in the objects' frames, before the set is chosen (at most one per object).
  struct Made {
    std::uint32_t object;
    geom::ContactModel model;
  };
  std::vector<Made> made;
  made.reserve(n);
  std::uint64_t last_pose_seq = 0, set_seq = 0;
  const std::int64_t min_period_ns = rate_hz_ > 0 ? std::int64_t(1e9 / rate_hz_) : 0;
  std::int64_t next_ns = rt::now_ns();
  while (!stop_.load(std::memory_order_acquire)) {
    if (min_period_ns > 0) {  // rate cap: at most one round per period
      const std::int64_t now = rt::now_ns();
      if (now < next_ns) {
        std::this_thread::sleep_for(std::chrono::nanoseconds(std::min<std::int64_t>(next_ns - now, 2'000'000)));
        continue;
      }
      next_ns = std::max(next_ns + min_period_ns, now);
    }
    poses_.update();
    const rt::PoseSample sample = poses_.output();
    if (sample.seq == 0 || sample.seq == last_pose_seq) {
      // No new pose: the haptic side publishes one per tick, so this wait is at most ~1 ms.
      std::this_thread::sleep_for(std::chrono::microseconds(100));
      continue;
    }
    last_pose_seq = sample.seq;
    const geom::Pose pose = geom::to_eigen(sample.pose);
    const std::int64_t t0 = rt::now_ns();
    ++set_seq;
    bool complete = true;
    made.clear();
    std::uint32_t pairs_total = 0;
    // This round's objects: those the probe's sphere reaches, and those still active (a builder
    // with history, a contact last round, a release still being sent), each once, in index order.
    work.clear();
    if (single) {
      work.push_back(0);
    } else {
      tree.query(probe_bound_.moved(pose), work, stack);  // the top level
      for (std::uint32_t k : work) near[k] = 1;
      for (std::uint32_t k : active_list)
        if (!near[k]) work.push_back(k);
      std::sort(work.begin(), work.end());
    }
    next_active.clear();
    std::uint32_t touched = 0;
    for (const std::uint32_t k : work) {
      const WorldObject& o = objects_[k];
      geom::ContactBuilder& builder = builders_[k];
      const geom::Pose rel = placed[k] ? geom::Pose(to_object[k] * pose) : pose;
      RoundOutput& out = outs[k];
      out.pairs.clear();
      out.complete = true;
      if (single || near[k]) {
        collide_(sample.seq, k, rel, out);
        ++object_stats_[k].reached;
        complete = complete && out.complete;
      }
      near[k] = 0;
      geom::ContactModel m = builder.build(probe_, *o.mesh, rel, out.pairs);
      m.seq = set_seq;
      m.pose_seq = sample.seq;
      m.pose_sampled_ns = sample.sampled_ns;
      pairs_total += m.pairs;
      ObjectRoundStats& os = object_stats_[k];
      os.peak_pairs = std::max(os.peak_pairs, m.pairs);
      if (m.in_contact()) {
        ++os.touching;
        ++touched;
        os.peak_penetration_mm = std::max(os.peak_penetration_mm, m.penetration_mm);
        if (m.penetration_mm > peak_pd_) {
          peak_pd_ = m.penetration_mm;
          peak_pose_ = rel;
          peak_pairs_ = out.pairs;
          peak_object_ = k;
        }
      } else if (was_contact[k]) {
        linger_until[k] = t0 + kLingerNs;  // it left this round: its release is sent for a while
      }
      const bool send = single || m.in_contact() || linger_until[k] > t0;
      was_contact[k] = m.in_contact();
      if (m.in_contact() || linger_until[k] > t0 || builder.has_first_face()) next_active.push_back(k);
      if (send) made.push_back({k, m});
    }
    active_list.swap(next_active);
    if (touched >= 2) ++multi_touch_rounds_;
    // The set: every object sent, the deepest first when there are more than it carries.
    geom::ContactSet& set = models_.input();
    set.count = 0;
    set.overflow = 0;
    set.contacts = 0;
    if (made.size() > geom::kMaxContactObjects) {
      std::partial_sort(made.begin(), made.begin() + geom::kMaxContactObjects, made.end(), [](const Made& a, const Made& b) {
        if (a.model.in_contact() != b.model.in_contact()) return a.model.in_contact();
        if (a.model.penetration_mm != b.model.penetration_mm) return a.model.penetration_mm > b.model.penetration_mm;
        return a.object < b.object;
      });
      for (std::size_t i = geom::kMaxContactObjects; i < made.size(); ++i) set.overflow += made[i].model.in_contact();
      if (set.overflow) ++overflow_rounds_;
      made.resize(geom::kMaxContactObjects);
    }
    double pd = 0;  // the deepest touched object's PD
    const std::int64_t published = rt::now_ns();
    for (Made& mk : made) {
      mk.model.published_ns = published;
      set.object[set.count] = mk.object;
      set.models[set.count] = placed[mk.object] ? geom::place(mk.model, objects_[mk.object].placement) : mk.model;
      ++set.count;
      set.contacts += mk.model.contacts;
      if (mk.model.in_contact()) pd = std::max(pd, mk.model.penetration_mm);
    }
    set.seq = set_seq;
    set.pose_seq = sample.seq;
    set.pose_sampled_ns = sample.sampled_ns;
    set.published_ns = published;
    models_.publish();
    const std::int64_t t1 = published;
    const std::uint32_t contacts = set.contacts;
    rounds_.fetch_add(1, std::memory_order_relaxed);
    // The live view: the probe in the world, every touched object's colliding faces (object k's
    // offset by the faces of the objects before it), the deepest touched object's model (world
    // frame) with the round's contacts.
    if (view_ && set.count > 0) {
      if (single) {
        view_->offer(set_seq, sample.seq, pose, outs[0].pairs, set.models[0], t1 - t0);
      } else if (view_->due()) {
        std::uint32_t show = 0;
        for (std::uint32_t i = 1; i < set.count; ++i)
          if (set.models[i].in_contact() &&
              (!set.models[show].in_contact() || set.models[i].penetration_mm > set.models[show].penetration_mm))
            show = i;
        view_pairs_.clear();
        for (const std::uint32_t k : work)
          for (const geom::FacePair& p : outs[k].pairs) view_pairs_.push_back({p.probe, face_offset[k] + p.object});
        geom::ContactModel shown = set.models[show];
        shown.contacts = set.contacts;
        view_->offer(set_seq, sample.seq, pose, view_pairs_, shown, t1 - t0);
      }
    }
    if (!complete) incomplete_.fetch_add(1, std::memory_order_relaxed);
    last_latency_ns_.store(t1 - t0, std::memory_order_relaxed);
    last_contacts_.store(contacts, std::memory_order_relaxed);
    if (status_) {
      rt::CollisionStatus st;
      st.updated_ns = t1;
      st.rounds = rounds_.load(std::memory_order_relaxed);
      st.model_seq = set_seq;
      st.pose_seq = sample.seq;
      st.latency_ns = t1 - t0;
      st.penetration_mm = pd;
      st.contacts = contacts;
      st.incomplete = static_cast<std::uint32_t>(incomplete_.load(std::memory_order_relaxed));
      status_->store(st);
    }
    latency_.record(t1 - t0);
    if (pairs_total > 0) contact_latency_.record(t1 - t0);
    const RoundRecord rec{t0, t1, sample.seq, pairs_total, contacts, pd, complete};
    if (records_.size() < max_rounds_) records_.push_back(rec);
    if (rounds_csv_ && rounds_error_.empty() &&
        std::fprintf(rounds_csv_, "%lld,%lld,%llu,%u,%u,%.6g,%d\n", static_cast<long long>(rec.start_ns),
                     static_cast<long long>(rec.end_ns), static_cast<unsigned long long>(rec.pose_seq), rec.pairs,
                     rec.contacts, rec.penetration_mm, rec.complete ? 1 : 0) < 0)
      rounds_error_ = rounds_path_ + ": write failed: " + std::strerror(errno);  // a full disk: once, then stop
  }
}

}  // namespace st::engine
