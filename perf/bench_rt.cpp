// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench exchange | haptic: the real-time core's two speed claims.
//  exchange: the haptic side's cost of taking the newest ContactModel (update + copy out) from a
//            TripleBuffer vs a std::mutex-guarded copy, the reader at 1 kHz, the writer
//            publishing flat out; both variants in the same run, alternating 1 s rounds, next to
//            the hardware floor (one word on a cache line the writer stores flat out).
//  haptic:   wake-up latency of the HapticLoop running the full servo tick (simulated device,
//            plane interpolation, saturation, telemetry, a stand-in collision thread at ~100 Hz)
//            next to a bare clock_nanosleep loop measured the same way, while a spinning thread
//            saturates the other core; alternating 5 s rounds, same run.
#include <pthread.h>
#include <sched.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bench.hpp"
#include "bench_json.hpp"
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/rt/clock.hpp>
#include <spheretouch/rt/haptic_loop.hpp>
#include <spheretouch/rt/haptic_servo.hpp>
#include <spheretouch/rt/histogram.hpp>
#include <spheretouch/rt/simulated_device.hpp>
#include <spheretouch/rt/telemetry.hpp>
#include <spheretouch/rt/triple_buffer.hpp>

namespace st::bench {

using rt::LatencyHistogram;
using rt::now_ns;

namespace {

void pin(int cpu) {
  if (cpu < 0) return;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  if (int e = pthread_setaffinity_np(pthread_self(), sizeof set, &set))
    std::fprintf(stderr, "warning: pinning to CPU %d refused: %s\n", cpu, std::strerror(e));
}

// Sleeps until an absolute CLOCK_MONOTONIC time.
void sleep_until(std::int64_t t) {
  const timespec ts = rt::to_timespec(t);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {}
}

// ---------------------------------------------------------------------------- exchange

struct MutexBox {
  std::mutex m;
  geom::ContactModel v;
};

struct ExchangeResult {
  std::unique_ptr<LatencyHistogram> read, publish;
  std::uint64_t fresh = 0, publishes = 0;
};

// One round: a writer thread publishing flat out, this thread reading at 1 kHz for `ms` ms.
template <class Publish, class Read>
void exchange_round(int ms, ExchangeResult& r, Publish publish, Read read, int reader_cpu, int writer_cpu) {
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> pubs{0};
  LatencyHistogram* ph = r.publish.get();
  std::thread writer([&] {
    pin(writer_cpu);
    geom::ContactModel m;
    std::uint64_t seq = 0, n = 0;
    while (!stop.load(std::memory_order_relaxed)) {
      m.seq = ++seq;
      m.penetration_mm = static_cast<double>(seq);
      // Time one publish in 64: timing every one would make the writer mostly clock reads.
      if ((n++ & 63) == 0) {
        const std::int64_t t0 = now_ns();
        publish(m);
        ph->record(now_ns() - t0);
      } else {
        publish(m);
      }
    }
    pubs.fetch_add(n, std::memory_order_relaxed);
  });
  pin(reader_cpu);
  geom::ContactModel out;
  std::int64_t deadline = now_ns() + 1'000'000;
  for (int i = 0; i < ms; ++i, deadline += 1'000'000) {
    sleep_until(deadline);
    const std::int64_t t0 = now_ns();
    const bool fresh = read(out);
    r.read->record(now_ns() - t0);
    r.fresh += fresh;
  }
  stop.store(true);
  writer.join();
  r.publishes += pubs.load();
}

void add_exchange_impl(CLI::App& app) {
  struct Args {
    double seconds = 10;
    bool json = false;
    int reader_cpu = -1, writer_cpu = -1;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "exchange", "Take-newest latency: TripleBuffer vs std::mutex copy (reader 1 kHz, writer flat out, same run)");
  cmd->add_option("--seconds", a->seconds, "measurement time per variant, s")->check(CLI::Range(1.0, 3600.0))->capture_default_str();
  cmd->add_option("--reader-cpu", a->reader_cpu, "pin the reader (-1: no)")->capture_default_str();
  cmd->add_option("--writer-cpu", a->writer_cpu, "pin the writer (-1: no)")->capture_default_str();
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->callback([a] {
    ExchangeResult tri{std::make_unique<LatencyHistogram>(), std::make_unique<LatencyHistogram>()};
    ExchangeResult mtx{std::make_unique<LatencyHistogram>(), std::make_unique<LatencyHistogram>()};
    ExchangeResult upd{std::make_unique<LatencyHistogram>(), std::make_unique<LatencyHistogram>()};
    ExchangeResult line{std::make_unique<LatencyHistogram>(), std::make_unique<LatencyHistogram>()};
    // The hardware floor: one 8-byte word on its own cache line that the writer stores flat out;
    // any protocol that shows the reader a value the other core just wrote pays at least this.
    struct alignas(rt::kCacheLine) Word {
      std::atomic<std::uint64_t> v{0};
    };
    auto word = std::make_unique<Word>();
    auto tb = std::make_unique<rt::TripleBuffer<geom::ContactModel>>();
    auto box = std::make_unique<MutexBox>();
    // Timer overhead, for reading the figures: an empty timed interval.
    LatencyHistogram timer;
    for (int i = 0; i < 100000; ++i) {
      const std::int64_t t0 = now_ns();
      timer.record(now_ns() - t0);
    }
    const int rounds = static_cast<int>(a->seconds);
    const int ms_last = static_cast<int>((a->seconds - rounds) * 1000);
    for (int i = 0; i <= rounds; ++i) {
      const int ms = i < rounds ? 1000 : ms_last;
      if (ms == 0) continue;
      exchange_round(
          ms, tri, [&](const geom::ContactModel& m) { tb->write(m); },
          [&](geom::ContactModel& o) { return tb->read(o); }, a->reader_cpu, a->writer_cpu);
      // update() alone: the index exchange without copying the 288 B payload out.
      exchange_round(
          ms, upd, [&](const geom::ContactModel& m) { tb->write(m); },
          [&](geom::ContactModel&) { return tb->update(); }, a->reader_cpu, a->writer_cpu);
      exchange_round(
          ms, line, [&](const geom::ContactModel& m) { word->v.store(m.seq, std::memory_order_release); },
          [&](geom::ContactModel& o) {
            const std::uint64_t v = word->v.load(std::memory_order_acquire);
            const bool fresh = v != o.seq;
            o.seq = v;
            return fresh;
          },
          a->reader_cpu, a->writer_cpu);
      exchange_round(
          ms, mtx,
          [&](const geom::ContactModel& m) {
            std::lock_guard<std::mutex> g(box->m);
            box->v = m;
          },
          [&](geom::ContactModel& o) {
            std::lock_guard<std::mutex> g(box->m);
            const bool fresh = o.seq != box->v.seq;
            o = box->v;
            return fresh;
          },
          a->reader_cpu, a->writer_cpu);
    }
    auto p = [](const LatencyHistogram& h, double q) { return static_cast<double>(h.percentile_ns(q)); };
    const double ratio50 = p(*mtx.read, 0.5) / std::max(1.0, p(*tri.read, 0.5));
    const double ratio99 = p(*mtx.read, 0.99) / std::max(1.0, p(*tri.read, 0.99));
    if (a->json) {
      // The histograms count whole nanoseconds: the percentiles go in as integers, as before.
      auto ns = [](const LatencyHistogram& h, double q) { return h.percentile_ns(q); };
      print_json({{"triple_ns_p50", ns(*tri.read, 0.5)},
                  {"triple_ns_p99", ns(*tri.read, 0.99)},
                  {"mutex_ns_p50", ns(*mtx.read, 0.5)},
                  {"mutex_ns_p99", ns(*mtx.read, 0.99)},
                  {"triple_ns_max", tri.read->max_ns()},
                  {"mutex_ns_max", mtx.read->max_ns()},
                  {"ratio_p50", round_to(ratio50, 2)},
                  {"ratio_p99", round_to(ratio99, 2)},
                  {"reads", tri.read->count()},
                  {"triple_publish_ns_p50", ns(*tri.publish, 0.5)},
                  {"triple_publish_ns_p99", ns(*tri.publish, 0.99)},
                  {"mutex_publish_ns_p50", ns(*mtx.publish, 0.5)},
                  {"mutex_publish_ns_p99", ns(*mtx.publish, 0.99)},
                  {"triple_publishes", tri.publishes},
                  {"mutex_publishes", mtx.publishes},
                  {"timer_ns_p50", ns(timer, 0.5)},
                  {"triple_update_only_ns_p50", ns(*upd.read, 0.5)},
                  {"triple_update_only_ns_p99", ns(*upd.read, 0.99)},
                  {"line_floor_ns_p50", ns(*line.read, 0.5)},
                  {"line_floor_ns_p99", ns(*line.read, 0.99)},
                  {"payload_bytes", sizeof(geom::ContactModel)}});
    } else {
      std::printf("take-newest ContactModel (%zu B), reader at 1 kHz, writer flat out, %.0f s per variant\n",
                  sizeof(geom::ContactModel), a->seconds);
      std::printf("%-14s %10s %10s %10s %10s %14s %14s\n", "variant", "read p50", "read p99", "read max", "reads",
                  "publish p50", "publishes");
      std::printf("%-14s %8.0f ns %7.0f ns %7lld ns %10llu %11.0f ns %14llu\n", "TripleBuffer", p(*tri.read, 0.5),
                  p(*tri.read, 0.99), static_cast<long long>(tri.read->max_ns()),
                  static_cast<unsigned long long>(tri.read->count()), p(*tri.publish, 0.5),
                  static_cast<unsigned long long>(tri.publishes));
      std::printf("%-14s %8.0f ns %7.0f ns %7lld ns %10llu %11.0f ns %14llu\n", "std::mutex", p(*mtx.read, 0.5),
                  p(*mtx.read, 0.99), static_cast<long long>(mtx.read->max_ns()),
                  static_cast<unsigned long long>(mtx.read->count()), p(*mtx.publish, 0.5),
                  static_cast<unsigned long long>(mtx.publishes));
      std::printf("%-14s %8.0f ns %7.0f ns %7lld ns %10llu   (index exchange only, no payload copy)\n", "Triple update",
                  p(*upd.read, 0.5), p(*upd.read, 0.99), static_cast<long long>(upd.read->max_ns()),
                  static_cast<unsigned long long>(upd.read->count()));
      std::printf("%-14s %8.0f ns %7.0f ns %7lld ns %10llu   (floor: one word the writer stores flat out)\n",
                  "Cache line", p(*line.read, 0.5), p(*line.read, 0.99), static_cast<long long>(line.read->max_ns()),
                  static_cast<unsigned long long>(line.read->count()));
      std::printf("mutex / triple: %.1fx at p50, %.1fx at p99 (timer overhead p50 %.0f ns, included)\n", ratio50,
                  ratio99, p(timer, 0.5));
    }
  });
}

// ---------------------------------------------------------------------------- haptic

geom::Mesh bench_wall() {
  geom::Mesh m;
  m.name = "wall";
  m.local = {{-100, -100, 0}, {100, -100, 0}, {100, 100, 0}, {-100, 100, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}
geom::Mesh bench_tip() {
  geom::Mesh m;
  m.name = "tip";
  m.local = {{0, 0, 0}, {1, 0, 2}, {-0.5, 0.866, 2}, {-0.5, -0.866, 2}};
  m.faces = {{0, 2, 1}, {0, 3, 2}, {0, 1, 3}, {1, 2, 3}};
  return m;
}

// Stand-in collision thread: tip faces with a vertex at or below the wall collide with both
// wall faces; ContactBuilder makes the model; ~100 Hz like a slow distributed round.
void stand_in_collision(rt::TripleBuffer<rt::PoseSample>& poses, rt::TripleBuffer<geom::ContactSet>& models,
                        std::atomic<bool>& stop) {
  const geom::Mesh w = bench_wall(), t = bench_tip();
  geom::ContactBuilder builder;
  std::vector<geom::ContactPair> pairs;
  std::uint64_t seq = 0;
  while (!stop.load(std::memory_order_relaxed)) {
    poses.update();
    const rt::PoseSample ps = poses.output();
    if (ps.seq != 0) {
      const geom::Pose pose = geom::to_eigen(ps.pose);
      pairs.clear();
      for (std::uint32_t f = 0; f < t.faces.size(); ++f) {
        bool below = false;
        for (std::uint32_t v : t.faces[f]) below |= (pose * t.local[v]).z() <= 0;
        if (below) {
          pairs.push_back({f, 0});
          pairs.push_back({f, 1});
        }
      }
      geom::ContactModel m = builder.build(t, w, pose, pairs);
      m.seq = ++seq;
      m.pose_seq = ps.seq;
      m.pose_sampled_ns = ps.sampled_ns;
      m.published_ns = now_ns();
      models.write(geom::ContactSet::of(m));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

struct LatencyStats {
  std::unique_ptr<LatencyHistogram> wake = std::make_unique<LatencyHistogram>();
  std::uint64_t ticks = 0, misses = 0;
};

// Bare loop: the same deadline schedule and measurement, no work.
void bare_round(std::int64_t periods, std::int64_t period_ns, LatencyStats& s) {
  rt::DeadlineSchedule sched(now_ns() + period_ns, period_ns);
  while (sched.index() < static_cast<std::uint64_t>(periods)) {
    sleep_until(sched.deadline_ns());
    const std::int64_t woke = now_ns();
    s.wake->record(woke - sched.deadline_ns());
    s.misses += sched.on_wake(woke);
    ++s.ticks;
    sched.advance();
  }
}

Json latency_json(const LatencyStats& s) {
  auto us = [&](double q) { return round_to(static_cast<double>(s.wake->percentile_ns(q)) / 1000.0, 1); };
  return {{"p50_us", us(0.5)},    {"p99_us", us(0.99)},
          {"p999_us", us(0.999)}, {"max_us", round_to(static_cast<double>(s.wake->max_ns()) / 1000.0, 1)},
          {"ticks", s.ticks},     {"misses", s.misses}};
}

void add_haptic_impl(CLI::App& app) {
  struct Args {
    double seconds = 60;
    double rate_hz = rt::kDefaultRateHz;
    int round_s = 5;
    bool json = false, no_load = false, mlock = false;
    int fifo = 0, cpu = -1, load_cpu = -1;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "haptic",
      "Wake-up latency: HapticLoop with the full servo tick vs a bare clock_nanosleep loop, other core loaded");
  cmd->add_option("--seconds", a->seconds, "measurement time per variant, s")->check(CLI::Range(1.0, 36000.0))->capture_default_str();
  cmd->add_option("--rate", a->rate_hz, "loop rate, Hz")->check(CLI::Range(rt::kMinRateHz, rt::kMaxRateHz))->capture_default_str();
  cmd->add_option("--round", a->round_s, "alternate the variants every this many seconds")
      ->check(CLI::Range(1, 3600))
      ->capture_default_str();
  cmd->add_option("--fifo", a->fifo, "SCHED_FIFO priority for both loops (0: off)")->check(CLI::Range(0, 99))->capture_default_str();
  cmd->add_option("--cpu", a->cpu, "pin both loops to this CPU (-1: no)")->capture_default_str();
  cmd->add_option("--load-cpu", a->load_cpu, "pin the load thread (-1: the CPU after --cpu, or unpinned)")->capture_default_str();
  cmd->add_flag("--mlock", a->mlock, "mlockall for both loops");
  cmd->add_flag("--no-load", a->no_load, "do not run the spinning load thread");
  cmd->add_flag("--json", a->json, "print one JSON object");
  cmd->callback([a] {
    const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / a->rate_hz);
    const long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
    int load_cpu = a->load_cpu;
    if (load_cpu < 0 && a->cpu >= 0 && ncpu > 1) load_cpu = static_cast<int>((a->cpu + 1) % ncpu);

    std::atomic<bool> stop_load{false};
    std::thread load;
    if (!a->no_load) {
      load = std::thread([&] {
        pin(load_cpu);
        volatile std::uint64_t x = 0;
        while (!stop_load.load(std::memory_order_relaxed)) x = x + 1;
      });
    }

    // The servo's world: device, buffers, collision stand-in, telemetry drained in-process.
    auto poses = std::make_unique<rt::TripleBuffer<rt::PoseSample>>();
    auto models = std::make_unique<rt::TripleBuffer<geom::ContactSet>>();
    rt::SimulatedDevice device(rt::builtin_press_slide({0, 0, 0}, {0, 0, 1}, 3.0, 20.0), rt::VirtualUser{}, 0);
    device.set_repeat(true);
    rt::Telemetry telemetry(rt::kDefaultTelemetryCapacity);
    rt::HapticServo servo(device, *poses, *models, rt::ForceLaw{}, rt::DefaultInterpolatorConfig(),
                          rt::DefaultSaturationConfig(), &telemetry);
    std::atomic<bool> stop_aux{false};
    std::thread collision([&] { stand_in_collision(*poses, *models, stop_aux); });
    std::thread drain([&] {
      std::vector<rt::TelemetrySample> buf(1024);
      while (!stop_aux.load(std::memory_order_relaxed)) {
        while (telemetry.drain_to(buf.data(), buf.size()) > 0) {}
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      }
    });

    rt::HapticLoopConfig lc = rt::DefaultHapticLoopConfig();
    lc.rate_hz = a->rate_hz;
    lc.fifo_priority = a->fifo;
    lc.cpu = a->cpu;
    lc.lock_memory = a->mlock;
    lc.prefault_stack_bytes = 256 * 1024;

    LatencyStats bare, loop;
    auto compute = std::make_unique<LatencyHistogram>();
    std::string rt_report;
    double remaining = a->seconds;
    while (remaining > 0) {
      const double chunk = std::min<double>(remaining, a->round_s);
      const auto periods = static_cast<std::int64_t>(chunk * a->rate_hz);
      // Bare loop on its own thread with the same real-time settings.
      std::thread bare_thread([&] {
        const rt::RtReport r = rt::HapticLoop::apply_realtime(lc);
        if (rt_report.empty()) rt_report = r.describe();
        bare_round(periods, period_ns, bare);
      });
      bare_thread.join();
      lc.max_periods = static_cast<std::uint64_t>(periods);
      auto hl = std::make_unique<rt::HapticLoop>(lc);
      auto started = hl->start(servo);
      if (!started) {
        std::fprintf(stderr, "%s\n", started.error().c_str());
        throw CLI::RuntimeError(2);
      }
      while (hl->running()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
      hl->stop();
      loop.wake->merge(hl->stats().wake_latency);
      compute->merge(hl->stats().tick_compute);
      loop.ticks += hl->stats().ticks;
      loop.misses += hl->stats().misses;
      remaining -= chunk;
    }
    stop_aux.store(true);
    collision.join();
    drain.join();
    stop_load.store(true);
    if (load.joinable()) load.join();

    const double compute_p999_us = static_cast<double>(compute->percentile_ns(0.999)) / 1000.0;
    const double ratio = static_cast<double>(loop.wake->percentile_ns(0.999)) /
                         std::max<double>(1.0, static_cast<double>(bare.wake->percentile_ns(0.999)));
    const rt::TelemetryStats ts = telemetry.stats();
    if (a->json) {
      print_json({{"bare", latency_json(bare)},
                  {"loop", latency_json(loop)},
                  {"tick_compute_p999_us", round_to(compute_p999_us, 2)},
                  {"tick_compute_p50_us", round_to(static_cast<double>(compute->percentile_ns(0.5)) / 1000.0, 2)},
                  {"tick_compute_max_us", round_to(static_cast<double>(compute->max_ns()) / 1000.0, 1)},
                  {"p999_ratio", round_to(ratio, 3)},
                  {"seconds", a->seconds},
                  {"rate_hz", a->rate_hz},
                  {"load", !a->no_load},
                  {"models", servo.stats().models},
                  {"telemetry_pushed", ts.pushed},
                  {"telemetry_dropped", ts.dropped},
                  {"rt", rt_report}});
    } else {
      std::printf("wake-up latency at %.0f Hz, %.0f s per variant, %s; real-time: %s\n", a->rate_hz, a->seconds,
                  a->no_load ? "no load" : "other core saturated", rt_report.c_str());
      std::printf("%-6s %10s %10s %10s %10s %10s %8s\n", "", "p50", "p99", "p99.9", "max", "ticks", "misses");
      for (const auto& row : {std::pair<const char*, const LatencyStats*>{"bare", &bare}, {"loop", &loop}}) {
        const char* name = row.first;
        const LatencyStats* s = row.second;  // not a structured binding: the lambda below captures it (clang < 16)
        auto us = [&](double q) { return static_cast<double>(s->wake->percentile_ns(q)) / 1000.0; };
        std::printf("%-6s %7.1f us %7.1f us %7.1f us %7.1f us %10llu %8llu\n", name, us(0.5), us(0.99), us(0.999),
                    static_cast<double>(s->wake->max_ns()) / 1000.0, static_cast<unsigned long long>(s->ticks),
                    static_cast<unsigned long long>(s->misses));
      }
      std::printf("loop / bare at p99.9: %.2fx; tick compute p50 %.2f us, p99.9 %.2f us, max %.1f us\n", ratio,
                  static_cast<double>(compute->percentile_ns(0.5)) / 1000.0, compute_p999_us,
                  static_cast<double>(compute->max_ns()) / 1000.0);
      std::printf("contact models taken %llu; telemetry pushed %llu, dropped %llu\n",
                  static_cast<unsigned long long>(servo.stats().models), static_cast<unsigned long long>(ts.pushed),
                  static_cast<unsigned long long>(ts.dropped));
    }
  });
}

}  // namespace

void add_exchange(CLI::App& app) { add_exchange_impl(app); }
void add_haptic(CLI::App& app) { add_haptic_impl(app); }

}  // namespace st::bench
