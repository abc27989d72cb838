// SPDX-License-Identifier: BSD-3-Clause
// libFuzzer target: the pose-file parser (geom/pose_io.hpp). Every accepted pose is a rigid
// transform within the documented tolerance, and format_pose / parse_poses round-trip it bit
// for bit (the writer promises shortest round-trip output).
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "fuzz_check.hpp"
#include <spheretouch/geom/pose_io.hpp>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  st::Result<std::vector<st::geom::Pose>> r = st::geom::parse_poses(text, "fuzz.txt");
  if (!r) {
    ST_FUZZ_CHECK(!r.error().empty(), "a refusal says why");
    return 0;
  }
  const std::vector<st::geom::Pose>& poses = r.value();
  ST_FUZZ_CHECK(!poses.empty(), "an accepted file has poses");
  std::string written;
  for (const st::geom::Pose& p : poses) {
    const Eigen::Matrix4d& m = p.matrix();
    ST_FUZZ_CHECK(m.allFinite(), "pose finite");
    ST_FUZZ_CHECK(m(3, 0) == 0 && m(3, 1) == 0 && m(3, 2) == 0 && m(3, 3) == 1, "last row 0 0 0 1");
    const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
    const double err = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    ST_FUZZ_CHECK(err <= st::geom::kPoseOrthonormalTolerance, "rotation orthonormal within tolerance");
    ST_FUZZ_CHECK(R.determinant() > 0, "rotation, not reflection");
    written += st::geom::format_pose(p) + "\n";
  }
  st::Result<std::vector<st::geom::Pose>> again = st::geom::parse_poses(written, "rewritten.txt");
  ST_FUZZ_CHECK(again.ok(), "format_pose output parses");
  ST_FUZZ_CHECK(again.value().size() == poses.size(), "same number of poses");
  for (std::size_t i = 0; i < poses.size(); ++i)
    ST_FUZZ_CHECK(std::memcmp(poses[i].matrix().data(), again.value()[i].matrix().data(), 16 * sizeof(double)) == 0,
                  "format_pose round-trips bit for bit");
  return 0;
}
