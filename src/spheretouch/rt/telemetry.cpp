// SPDX-License-Identifier: BSD-3-Clause
#include <spheretouch/rt/telemetry.hpp>

#include <cerrno>
#include <chrono>
#include <cstring>

namespace st::inline SPHERETOUCH_ABI::rt {

Telemetry::Telemetry(std::size_t capacity) : queue_(capacity) {}

Result<std::unique_ptr<Telemetry>> Telemetry::open(const std::string& path, std::size_t capacity) {
  if (capacity == 0) return fail("telemetry: capacity 0, expected >= 1");
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return fail("telemetry: cannot open '", path, "' for writing: ", std::strerror(errno));
  std::setvbuf(f, nullptr, _IOFBF, 1 << 20);
  std::fputs(
      "tick,t_ns,latency_ns,pose_seq,model_seq,model_age_ns,x_mm,y_mm,z_mm,fx_N,fy_N,fz_N,pd_mm,fade,ceiling_N,flags,"
      "misses,proxy_x_mm,proxy_y_mm,proxy_z_mm,tx_Nm,ty_Nm,tz_Nm\n",
      f);
  auto t = std::make_unique<Telemetry>(capacity);
  t->file_ = f;
  t->path_ = path;
  t->writer_ = std::thread([p = t.get()] { p->writer_loop(); });
  return t;
}

Telemetry::~Telemetry() { close(); }

std::size_t Telemetry::drain_to(TelemetrySample* out, std::size_t max) noexcept {
  std::size_t n = 0;
  while (n < max && queue_.try_pop(out[n])) ++n;
  return n;
}

void Telemetry::write(const TelemetrySample& s) {
  if (failed_.load(std::memory_order_relaxed)) return;
  const int n = std::fprintf(file_,
                             "%llu,%lld,%lld,%llu,%llu,%lld,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g,%.4g,%.4g,%u,%u,%.9g,%."
                             "9g,%.9g,%.6g,%.6g,%.6g\n",
                             static_cast<unsigned long long>(s.tick), static_cast<long long>(s.t_ns),
                             static_cast<long long>(s.latency_ns), static_cast<unsigned long long>(s.pose_seq),
                             static_cast<unsigned long long>(s.model_seq), static_cast<long long>(s.model_age_ns),
                             s.position_mm[0], s.position_mm[1], s.position_mm[2], s.force_N[0], s.force_N[1],
                             s.force_N[2], s.penetration_mm, s.fade, s.ceiling_N, s.flags, s.misses, s.proxy_mm[0],
                             s.proxy_mm[1], s.proxy_mm[2], s.torque_Nm[0], s.torque_Nm[1], s.torque_Nm[2]);
  if (n < 0) {  // a full disk: say which file and why, once, and stop writing
    error_ = path_ + ": write failed: " + std::strerror(errno);
    failed_.store(true, std::memory_order_release);
    return;
  }
  written_.fetch_add(1, std::memory_order_relaxed);
}

std::string Telemetry::error() const { return failed_.load(std::memory_order_acquire) ? error_ : std::string(); }

void Telemetry::writer_loop() {
  TelemetrySample s;
  for (;;) {
    const bool stopping = stop_.load(std::memory_order_acquire);
    bool any = false;
    while (queue_.try_pop(s)) {
      write(s);
      any = true;
    }
    if (stopping) break;  // drained after the stop request was seen: nothing is left behind
    if (!any) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

void Telemetry::close() {
  if (writer_.joinable()) {
    stop_.store(true, std::memory_order_release);
    writer_.join();
  }
  if (file_) {
    const TelemetryStats st = stats();
    std::fprintf(file_, "# samples pushed %llu, written %llu, dropped %llu (queue full)\n",
                 static_cast<unsigned long long>(st.pushed), static_cast<unsigned long long>(st.written),
                 static_cast<unsigned long long>(st.dropped));
    // Buffered bytes reach the disk only now: a full disk shows up in the flush or the close.
    const bool flushed = std::fflush(file_) == 0 && std::ferror(file_) == 0;
    const int flush_errno = errno;
    const bool closed = std::fclose(file_) == 0;
    if (!failed_.load(std::memory_order_relaxed) && (!flushed || !closed)) {
      error_ = path_ + ": write failed: " + std::strerror(flushed ? errno : flush_errno);
      failed_.store(true, std::memory_order_release);
    }
    file_ = nullptr;
  }
}

TelemetryStats Telemetry::stats() const {
  return {pushed_.load(std::memory_order_relaxed), dropped_.load(std::memory_order_relaxed),
          written_.load(std::memory_order_relaxed)};
}

}  // namespace st::rt
