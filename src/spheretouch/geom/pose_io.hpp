// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Pose files: one rigid transform per line as 16 numbers separated by whitespace
/// (spaces/tabs; commas are not separators), a row-major 4×4 matrix whose last row is 0 0 0 1;
/// '#' starts a comment to the end of the line, blank lines are ignored. Checked where they enter.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Largest accepted entry of |RᵀR − I| for the rotation block: catches typos and reflections,
/// lets through matrices printed with ~7 significant digits. Accepted poses are kept as written.
inline constexpr double kPoseOrthonormalTolerance = 1e-6;

/// Empty when m is a rigid transform (finite; last row 0 0 0 1; max |RᵀR − I| entry <= tolerance;
/// det R > 0), else what is wrong. The one rigid-transform check of pose files, the wire and the
/// Python module.
std::string check_rigid(const Eigen::Matrix4d& m, double tolerance = kPoseOrthonormalTolerance);

/// A pose and the newest comment before it (or on its line), text after '#', trailing blanks cut:
/// tools annotate poses that way ("# contacts 105 (target 100)").
struct PoseLine {
  Pose pose;            ///< the pose, as read
  std::string comment;  ///< "" when there is none
};
/// A pose file is a text file of at most this many bytes (about 1.5 million poses).
inline constexpr std::uint64_t kMaxPoseFileBytes = 512ull << 20;
/// Every pose of a pose file with its comment; errors as read_poses (and a file that is not a
/// regular one, or is over kMaxPoseFileBytes, is refused before it is read).
Result<std::vector<PoseLine>> read_pose_lines(const std::string& path);
/// parse_poses with comments.
Result<std::vector<PoseLine>> parse_pose_lines(std::string_view text, std::string_view name);

/// Reads every pose of a pose file; an error names path:line and what is wrong.
Result<std::vector<Pose>> read_poses(const std::string& path);

/// Parses pose-file text; `name` (usually the path) prefixes error messages.
Result<std::vector<Pose>> parse_poses(std::string_view text, std::string_view name);

/// One pose-file line (no newline): 16 numbers, shortest round-trip form, so parsing it back
/// gives the identical matrix.
std::string format_pose(const Pose& pose);

}  // namespace st::geom
