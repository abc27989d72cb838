// Collision thread: see collision_loop.hpp.
#include "app/collision_loop.hpp"

#include <chrono>

#include "geom/pod.hpp"
#include "rt/clock.hpp"

namespace st::app {

CollisionLoop::CollisionLoop(const geom::Mesh& probe, const geom::Mesh& object, rt::TripleBuffer<rt::PoseSample>& poses,
                             rt::TripleBuffer<geom::ContactModel>& models, CollideFn collide, double rate_hz,
                             std::size_t max_rounds)
    : probe_(probe), object_(object), poses_(poses), models_(models), collide_(std::move(collide)), rate_hz_(rate_hz),
      max_rounds_(max_rounds) {
  records_.reserve(max_rounds_);
}

CollisionLoop::~CollisionLoop() { stop(); }

void CollisionLoop::start() { thread_ = std::thread([this] { run(); }); }

void CollisionLoop::stop() {
  stop_.store(true, std::memory_order_release);
  if (thread_.joinable()) thread_.join();
}

void CollisionLoop::run() {
  geom::ContactBuilder builder;
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
    if (!out.complete) incomplete_.fetch_add(1, std::memory_order_relaxed);
    last_latency_ns_.store(t1 - t0, std::memory_order_relaxed);
    last_contacts_.store(m.contacts, std::memory_order_relaxed);
    if (records_.size() < max_rounds_)
      records_.push_back({t0, t1, sample.seq, m.pairs, m.contacts, m.penetration_mm, out.complete});
    if (m.in_contact() && m.penetration_mm > peak_pd_) {
      peak_pd_ = m.penetration_mm;
      peak_pose_ = pose;
      peak_pairs_ = out.pairs;
    }
  }
}

}  // namespace st::app
