// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the scene-file parser (app/scene.hpp, TOML via toml++). parse_scene loads no
// mesh: for a named mesh or trajectory file it only asks whether the file exists (a stat), so
// the target touches nothing on disk. Relative paths and "model:NAME" resolve in
// tests/fuzz/scene_files/ (empty placeholders), so the same input always takes the same path.
// A scene that parses must hold only values the rest of the program can use unchecked.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>

#include <spheretouch/engine/scene.hpp>
#include "fuzz_check.hpp"

#ifndef ST_FUZZ_SCENE_DIR
#error "ST_FUZZ_SCENE_DIR (tests/fuzz/scene_files) is set by tests/fuzz/meson.build"
#endif

namespace {

void check_body(const st::engine::BodySpec& b) {
  ST_FUZZ_CHECK(b.mesh.empty() != b.builtin.empty(), "a body is a mesh or a builtin shape");
  ST_FUZZ_CHECK(std::isfinite(b.radius_mm) && b.radius_mm > 0, "radius");
  ST_FUZZ_CHECK(std::isfinite(b.length_mm) && b.length_mm >= 0, "length");
  ST_FUZZ_CHECK(std::isfinite(b.size_mm) && b.size_mm > 0, "size");
  ST_FUZZ_CHECK(std::isfinite(b.scale) && b.scale > 0, "scale");
  ST_FUZZ_CHECK(b.frequency >= 1 && b.segments >= 3, "resolution");
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  setenv("ST_MODEL_DIR", ST_FUZZ_SCENE_DIR, 1);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  st::Result<st::engine::Scene> r = st::engine::parse_scene(text, "fuzz.toml", ST_FUZZ_SCENE_DIR);
  if (!r) {
    ST_FUZZ_CHECK(!r.error().empty(), "a refusal says why");
    return 0;
  }
  const st::engine::Scene& s = r.value();
  check_body(s.probe);
  check_body(s.object);
  ST_FUZZ_CHECK(s.probe_tip.allFinite() && s.probe_rotation_deg.allFinite(), "probe tip and rotation finite");
  ST_FUZZ_CHECK(s.device.target.allFinite(), "device target finite");
  ST_FUZZ_CHECK(s.device.normal.allFinite() && std::abs(s.device.normal.norm() - 1) < 1e-9,
                "device normal is a unit vector");
  ST_FUZZ_CHECK(std::isfinite(s.device.press_mm) && std::isfinite(s.device.slide_mm), "press and slide finite");
  ST_FUZZ_CHECK(s.workers >= 0 && s.workers <= 64, "worker count");
  for (const std::string& ep : s.endpoints)
    ST_FUZZ_CHECK(ep.rfind("tcp://", 0) == 0 || ep.rfind("ipc://", 0) == 0, "endpoint scheme");
  ST_FUZZ_CHECK(std::isfinite(s.deadline_ms) && s.deadline_ms > 0, "deadline");
  ST_FUZZ_CHECK(std::isfinite(s.duration_s) && s.duration_s > 0, "duration");
  ST_FUZZ_CHECK(std::isfinite(s.collision_rate_hz) && s.collision_rate_hz >= 0, "collision rate");
  ST_FUZZ_CHECK(s.interp.crossfade_ns >= 0 && s.interp.stale_timeout_ns > 0 && s.interp.fade_ns >= 0,
                "interpolation times");
  ST_FUZZ_CHECK(st::rt::ForceLaw::make(s.law).ok(), "the force law is constructible");
  ST_FUZZ_CHECK(st::rt::Saturator::check(s.saturation).empty(), "saturation config valid");
  ST_FUZZ_CHECK(st::rt::HapticLoop::check(s.haptic).empty(), "haptic config valid");
  return 0;
}
