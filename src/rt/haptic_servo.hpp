// HapticServo: the haptic thread's tick (DESIGN.md data flow), as a TickHandler for HapticLoop:
// read the device pose → publish it → take the newest ContactModel if one arrived →
// interpolate the force → saturate → command the device → push one telemetry sample.
// Everything it touches is preallocated; the tick takes no lock and never waits.
#pragma once
#include <cstdint>

#include "geom/contact.hpp"
#include "rt/device.hpp"
#include "rt/haptic_loop.hpp"
#include "rt/interpolator.hpp"
#include "rt/pose_sample.hpp"
#include "rt/saturation.hpp"
#include "rt/telemetry.hpp"
#include "rt/triple_buffer.hpp"

namespace st::rt {

/// Counters of a servo (read after the loop stopped, or racily for display).
struct ServoStats {
  std::uint64_t ticks = 0;          ///< ticks served
  std::uint64_t models = 0;         ///< contact models taken
  std::uint64_t pose_failures = 0;  ///< device could not deliver a pose (zero force commanded)
  std::uint64_t saturated = 0;      ///< ticks where the saturator cut the force
};

/// The servo tick. Construct it, hand it to HapticLoop::start()/run().
class HapticServo final : public TickHandler {
 public:
  /// All references must outlive the servo; telemetry may be null. The saturation peak is
  /// lowered to the device's max_force_N() if it is above it.
  HapticServo(Device& device, TripleBuffer<PoseSample>& poses, TripleBuffer<geom::ContactModel>& models,
              const ForceLaw& law, const InterpolatorConfig& interp, SaturationConfig saturation,
              Telemetry* telemetry);
  void tick(const TickInfo& info) noexcept override;
  const ServoStats& stats() const { return stats_; }             ///< counters
  const Interpolator& interpolator() const { return interp_; }   ///< for inspection
  const Saturator& saturator() const { return sat_; }            ///< for inspection

 private:
  Device& device_;
  TripleBuffer<PoseSample>& poses_;
  TripleBuffer<geom::ContactModel>& models_;
  Interpolator interp_;
  Saturator sat_;
  Telemetry* telemetry_;
  ServoStats stats_;
  std::uint64_t pose_seq_ = 0;
  std::int64_t last_ns_ = 0;
  std::int64_t model_pose_ns_ = 0;  ///< pose_sampled_ns of the newest model
};

}  // namespace st::rt
