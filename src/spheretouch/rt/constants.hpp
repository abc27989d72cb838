// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Constants of the real-time core, each with its unit and the reason for its value.
/// Device figures are the SensAble/3D Systems PHANToM Omni (Touch) data sheet, the device of the
/// paper (§3.1); the loop rate is OpenHaptics' servo loop and the paper's "1 KHz" (§3.2).
#pragma once
#include <spheretouch/abi.hpp>
#include <cstddef>
#include <cstdint>

namespace st::inline SPHERETOUCH_ABI::rt {

/// Bytes in a cache line on x86-64 and most ARMv8 cores; the unit of false-sharing padding.
/// (std::hardware_destructive_interference_size is also 64 here but warns as ABI-unstable.)
inline constexpr std::size_t kCacheLine = 64;

/// Haptic servo rate, Hz: the Omni's I/O update rate (paper §3.2) and OpenHaptics' servo loop.
inline constexpr double kDefaultRateHz = 1000.0;
/// Highest rate the loop accepts, Hz: above 20 kHz the 50 µs period is below typical wake-up
/// latency of a non-RT kernel, so every tick would be a miss.
inline constexpr double kMaxRateHz = 20000.0;
/// Lowest rate the loop accepts, Hz: below 1 Hz a "haptic" loop is a misconfiguration.
inline constexpr double kMinRateHz = 1.0;

/// Omni peak force, N (data sheet "maximum exertable force at nominal position").
inline constexpr double kOmniPeakForceN = 3.3;
/// Omni continuous force, N (data sheet "continuous exertable force, 24 hrs").
inline constexpr double kOmniContinuousForceN = 0.88;
/// Stiffness an Omni renders stably at 1 kHz, N/mm: the data sheet gives 1.02–2.31 N/mm per
/// axis for the mechanism; rendered virtual walls chatter above about 0.5–0.7 N/mm in practice.
inline constexpr double kOmniStableStiffnessNPerMm = 0.7;

/// Paper eq. (1) constant a (dimensionless, "experience value", §3.6).
inline constexpr double kPaperA = 3.0;
/// Paper eq. (1) constant b, N (multiplies a dimensionless log, so it carries the unit).
inline constexpr double kPaperB = 0.8;
/// Default base of the log in the paper's equation (1): e. The paper writes "log"; with base e the
/// law's steepest (tangent) segment has slope b·e^(a-1)/u, see kDefaultPdUnitMm.
inline constexpr double kDefaultLogBase = 2.718281828459045;
/// Default unit of PD inside equation (1), mm: 10 mm (cm). With base e the continuous law (linear from
/// the origin, tangent to the log curve) has maximum stiffness 0.8·e²/10 = 0.591 N/mm, inside the
/// Omni's stable range; with PD in mm it would be 5.9 N/mm, ten times too stiff.
inline constexpr double kDefaultPdUnitMm = 10.0;
/// Linear comparison spring, N/mm: middle of the Omni's stable range.
inline constexpr double kDefaultSpringNPerMm = 0.5;

/// Time constant of the sustained-force (I²t-like) estimate, s: motor windings heat over tens of
/// seconds, so 10 s lets short presses reach the peak while a long push settles to continuous.
inline constexpr double kSustainedTauS = 10.0;
/// Fraction of the continuous force at which the sustained limiter starts to pull the ceiling
/// down from peak (so the ceiling moves smoothly instead of switching).
inline constexpr double kSustainedOnset = 0.8;

/// Age of the newest contact model after which the force starts fading, ns: 200 ms. Our
/// collision side answers in a few ms; 200 ms without an answer means it is stuck or dead.
inline constexpr std::int64_t kDefaultStaleTimeoutNs = 200'000'000;
/// Duration of the fade to zero after the stale timeout, ns: 100 ms is slow enough not to kick
/// the user's hand and fast enough that a dead collision side cannot hold a force.
inline constexpr std::int64_t kDefaultFadeNs = 100'000'000;
/// Cross-fade between an old and a new contact plane, ns: 10 ms, about one collision round
/// (the paper's collision thread is ~25× slower than the 1 ms servo tick, §3.6).
inline constexpr std::int64_t kDefaultCrossfadeNs = 10'000'000;
/// The cross-fade lasts at most this many of the recent intervals between models (an average):
/// it hides what consecutive models disagree on, and two rounds are enough for that; at a fast
/// update rate a fixed 10 ms would smooth over five rounds and the direction would lag the
/// geometry (a ridge crossed at 300 mm/s: p90 9.5° from the FD at the tick's own pose with 10 ms
/// and models every 2 ms, 7.9° with 8 ms, 4.3° with 4 ms, but 4 ms let the hand on the
/// elephant gain +0.005 mJ a cycle in closed loop, 8 ms -0.005; `spheretouch-bench force`).
inline constexpr double kCrossfadeRounds = 4.0;
/// When a model says "no contact" after one in contact, the old model is still evaluated at each
/// tick's pose (it follows the probe out along its normal) under a weight that falls to zero over
/// this long, ns, and never rises: the force ends with the contact instead of being faded over
/// the full cross-fade (0.18-0.63 N kept at 0.1 mm clear measured), in steps of <= 1/4 of it.
inline constexpr std::int64_t kReleaseFadeNs = 4'000'000;
/// Paper §3.7 interpolation gain turning the probe movement D (mm) into force, N/mm.
inline constexpr double kDefaultPaperGainNPerMm = 0.5;
/// Largest probe movement the paper interpolation extrapolates from, mm: bounds B = A + D so a
/// stalled collision side cannot make the extrapolated force grow without limit.
inline constexpr double kDefaultPaperMaxMoveMm = 2.0;

/// Smallest force the interpolator outputs, N: anything below is rendered as exactly 0. The
/// plane cross-fade decays a released force geometrically; without a floor it would never reach
/// zero. 1 µN is four orders of magnitude below an Omni's force resolution (~10 mN).
inline constexpr double kMinRenderedForceN = 1e-6;

/// Telemetry queue capacity, samples: 8 s at 1 kHz of slack for a stalled disk.
inline constexpr std::size_t kDefaultTelemetryCapacity = 8192;

/// Bins per octave of the latency histograms: 2^6 = 64, i.e. ≤ 1.6 % relative bin width.
inline constexpr int kHistSubBits = 6;
/// Octaves covered by the latency histograms: 2^40 ns ≈ 18 min; larger values land in the top bin.
inline constexpr int kHistOctaves = 40;

}  // namespace st::rt
