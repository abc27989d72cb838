// SPDX-License-Identifier: BSD-3-Clause
// spheretouch-bench hostile: the attacks on the run's surfaces other than the workers, the UDP
// device bridge and the live view (security review, items 2 and 3), each against the real
// component started in this process.
#pragma once
#include <chrono>
#include <memory>
#include <string>

namespace st::bench {

/// What an attack on a surface achieved.
struct SurfaceOutcome {
  bool refused = false;  ///< every attack refused and the honest user unaffected
  std::string note;      ///< the figures behind it
};

/// An authenticated UDP bridge with a driver sending signed poses at 1 kHz; forged datagrams
/// (unsigned version 1, a wrong key, a 2^64 − 1 sequence number) sent from the driver's own
/// socket for `window`. Refused when the pose handed to the servo never moved.
SurfaceOutcome forged_udp(std::chrono::milliseconds window);

/// A live view served from this process (the largest frames, 60 Hz) for the view attacks.
class ViewFixture {
 public:
  ViewFixture();
  ~ViewFixture();
  ViewFixture(const ViewFixture&) = delete;
  ViewFixture& operator=(const ViewFixture&) = delete;
  /// WebSocket handshakes from another site's page, a rebound host name and without the token,
  /// repeated for `window`: refused when each gets 403 and the view's own page then 101.
  SurfaceOutcome foreign_origin(std::chrono::milliseconds window);
  /// One page that stops reading while another reads for `window`: refused when the reading
  /// page gets more than 30 frames a second.
  SurfaceOutcome stalled_page(std::chrono::milliseconds window);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string error_;  // the view did not start
};

}  // namespace st::bench
