// SPDX-License-Identifier: BSD-3-Clause
// Collision thread: see collision_loop.hpp.
#include <spheretouch/engine/collision_loop.hpp>

#include <cerrno>
#include <chrono>
#include <cstring>

#include <spheretouch/geom/pod.hpp>
#include <spheretouch/rt/clock.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

CollisionLoop::CollisionLoop(const geom::Mesh& probe, const geom::Mesh& object, rt::TripleBuffer<rt::PoseSample>& poses,
                             rt::TripleBuffer<geom::ContactModel>& models, CollideFn collide, double rate_hz,
                             std::size_t max_rounds, const geom::ContactConfig& contact)
    : probe_(probe),
      object_(object),
      poses_(poses),
      models_(models),
      collide_(std::move(collide)),
      builder_(contact),
      rate_hz_(rate_hz),
      max_rounds_(max_rounds) {
  records_.reserve(max_rounds_);
  builder_.prepare(probe_, object_);
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
  geom::ContactBuilder& builder = builder_;
  RoundOutput out;
  std::uint64_t last_pose_seq = 0, model_seq = 0;
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
    out.pairs.clear();
    out.complete = true;
    collide_(sample.seq, pose, out);
    geom::ContactModel m = builder.build(probe_, object_, pose, out.pairs);
    m.seq = ++model_seq;
    m.pose_seq = sample.seq;
    m.pose_sampled_ns = sample.sampled_ns;
    m.published_ns = rt::now_ns();
    models_.write(m);
    const std::int64_t t1 = m.published_ns;
    rounds_.fetch_add(1, std::memory_order_relaxed);
    if (view_) view_->offer(m.seq, sample.seq, pose, out.pairs, m, t1 - t0);
    if (!out.complete) incomplete_.fetch_add(1, std::memory_order_relaxed);
    last_latency_ns_.store(t1 - t0, std::memory_order_relaxed);
    last_contacts_.store(m.contacts, std::memory_order_relaxed);
    if (status_) {
      rt::CollisionStatus st;
      st.updated_ns = t1;
      st.rounds = rounds_.load(std::memory_order_relaxed);
      st.model_seq = m.seq;
      st.pose_seq = sample.seq;
      st.latency_ns = t1 - t0;
      st.penetration_mm = m.penetration_mm;
      st.contacts = m.contacts;
      st.incomplete = static_cast<std::uint32_t>(incomplete_.load(std::memory_order_relaxed));
      status_->store(st);
    }
    latency_.record(t1 - t0);
    const RoundRecord rec{t0, t1, sample.seq, m.pairs, m.contacts, m.penetration_mm, out.complete};
    if (records_.size() < max_rounds_) records_.push_back(rec);
    if (rounds_csv_ && rounds_error_.empty() &&
        std::fprintf(rounds_csv_, "%lld,%lld,%llu,%u,%u,%.6g,%d\n", static_cast<long long>(rec.start_ns),
                     static_cast<long long>(rec.end_ns), static_cast<unsigned long long>(rec.pose_seq), rec.pairs,
                     rec.contacts, rec.penetration_mm, rec.complete ? 1 : 0) < 0)
      rounds_error_ = rounds_path_ + ": write failed: " + std::strerror(errno);  // a full disk: once, then stop
    if (m.in_contact() && m.penetration_mm > peak_pd_) {
      peak_pd_ = m.penetration_mm;
      peak_pose_ = pose;
      peak_pairs_ = out.pairs;
    }
  }
}

}  // namespace st::engine
