// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// PoseSample: the device pose the haptic thread publishes each tick for the collision thread.
/// Plain data with a sequence number and the sampling time, so the collision side can stamp its
/// ContactModel with the pose it was computed at.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <type_traits>

#include <spheretouch/geom/pod.hpp>

namespace st::inline SPHERETOUCH_ABI::rt {

/// One device pose sample.
struct PoseSample {
  std::uint64_t seq = 0;        ///< 1, 2, 3... per publisher; 0 = none yet
  std::int64_t sampled_ns = 0;  ///< when the device was read, CLOCK_MONOTONIC ns
  geom::PodPose pose;           ///< probe file → object file coordinates, mm
};
static_assert(std::is_trivially_copyable_v<PoseSample> && sizeof(PoseSample) == 112);

}  // namespace st::rt
