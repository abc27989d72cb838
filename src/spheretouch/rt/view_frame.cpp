// SPDX-License-Identifier: BSD-3-Clause
// ViewFrame checks: see view_frame.hpp.
#include <spheretouch/rt/view_frame.hpp>

#include <cmath>

namespace st::inline SPHERETOUCH_ABI::rt {

bool sanitize_view_frame(ViewFrame& f, std::uint32_t probe_faces, std::uint32_t object_faces, const char** why) noexcept {
  auto refuse = [why](const char* w) {
    if (why) *why = w;
    return false;
  };
  auto finite = [](double& v) {
    if (!std::isfinite(v)) v = 0;
  };
  for (double& v : f.pose) finite(v);
  for (double& v : f.force_dir) finite(v);
  for (double& v : f.contact_point) finite(v);
  finite(f.penetration_mm);
  finite(f.round_ms);
  f.flags &= ViewFrame::kKnownFlags;
  if (f.n_probe > kViewMaxFaces || f.n_object > kViewMaxFaces) return refuse("a face count over the frame's capacity");
  for (std::uint32_t i = 0; i < f.n_probe; ++i)
    if (f.faces[i] >= probe_faces) return refuse("a probe face id beyond the probe's faces");
  for (std::uint32_t i = f.n_probe; i < f.n_probe + f.n_object; ++i)
    if (f.faces[i] >= object_faces) return refuse("an object face id beyond the object's faces");
  return true;
}

}  // namespace st::rt
