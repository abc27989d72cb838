// SPDX-License-Identifier: BSD-3-Clause
// Pose file reading and writing. Numbers go through std::from_chars / std::to_chars: correctly
// rounded, locale-independent, and shortest-round-trip on output, so a written pose reads back
// bit for bit.
#include <spheretouch/geom/pose_io.hpp>
#include <spheretouch/geom/text_file.hpp>

#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace st::inline SPHERETOUCH_ABI::geom {
namespace {

constexpr int kValues = 16;

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/// Parses one whole token as a double. Accepts what from_chars accepts plus one leading '+'.
/// Returns an empty string on success, else the reason the token is not a number.
std::string parse_number(std::string_view tok, double& out) {
  std::string_view s = tok;
  if (s.size() > 1 && s[0] == '+' && s[1] != '-' && s[1] != '+') s.remove_prefix(1);
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  if (ec == std::errc::result_out_of_range) return "is out of the range of a double";
  if (ec != std::errc() || end != s.data() + s.size()) return "is not a number";
  return {};
}

std::string join_values(const double* v, int n) {
  std::ostringstream os;
  os.precision(17);
  for (int i = 0; i < n; ++i) os << (i ? " " : "") << v[i];
  return os.str();
}

Result<std::vector<Pose>> poses_only(const Result<std::vector<PoseLine>>& lines) {
  if (!lines) return Error{lines.error()};
  std::vector<Pose> poses;
  poses.reserve(lines.value().size());
  for (const PoseLine& l : lines.value()) poses.push_back(l.pose);
  return poses;
}

}  // namespace

std::string check_rigid(const Eigen::Matrix4d& m, double tolerance) {
  if (!m.allFinite()) return "not finite";
  if (m(3, 0) != 0.0 || m(3, 1) != 0.0 || m(3, 2) != 0.0 || m(3, 3) != 1.0) {
    const double last[4] = {m(3, 0), m(3, 1), m(3, 2), m(3, 3)};
    return "last row must be 0 0 0 1, found " + join_values(last, 4);
  }
  const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
  const double err = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(err <= tolerance)) {
    std::ostringstream os;
    os << "rotation block is not orthonormal: max |R^T R - I| entry is " << err << " > " << tolerance;
    return os.str();
  }
  const double det = r.determinant();
  if (det <= 0.0) {
    std::ostringstream os;
    os << "rotation block is not a rotation (reflection): det = " << det;
    return os.str();
  }
  return {};
}

Result<std::vector<PoseLine>> parse_pose_lines(std::string_view text, std::string_view name) {
  std::vector<PoseLine> poses;
  std::string comment;  // the newest comment since the previous pose
  std::size_t line_no = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    ++line_no;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) {
      comment.assign(line.substr(hash + 1));
      while (!comment.empty() && (is_space(comment.back()) || comment.back() == '\r')) comment.pop_back();
      line = line.substr(0, hash);
    }

    std::array<double, kValues> v{};
    int count = 0;
    std::size_t i = 0;
    while (i < line.size()) {
      if (is_space(line[i])) {
        ++i;
        continue;
      }
      std::size_t j = i;
      while (j < line.size() && !is_space(line[j])) ++j;
      const std::string_view tok = line.substr(i, j - i);
      double x = 0.0;
      const std::string why = parse_number(tok, x);
      if (!why.empty())
        return fail(name, ":", line_no, ": value ", count + 1, " (column ", i + 1, ") '", tok, "' ", why);
      if (!std::isfinite(x))
        return fail(name, ":", line_no, ": value ", count + 1, " (column ", i + 1, ") '", tok, "' is not finite");
      if (count < kValues) v[count] = x;
      ++count;
      i = j;
    }
    if (count == 0) continue;  // blank or comment-only line
    if (count != kValues)
      return fail(name, ":", line_no, ": expected ", kValues, " numbers (a row-major 4x4 rigid transform), found ", count);
    Pose pose = Pose::Identity();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) pose.matrix()(r, c) = v[4 * r + c];
    if (const std::string why = check_rigid(pose.matrix()); !why.empty()) return fail(name, ":", line_no, ": ", why);
    poses.push_back({pose, std::move(comment)});
    comment.clear();
  }
  if (poses.empty()) return fail(name, ": no poses (the file is empty or has only comments)");
  return poses;
}

Result<std::vector<Pose>> parse_poses(std::string_view text, std::string_view name) {
  return poses_only(parse_pose_lines(text, name));
}

Result<std::vector<PoseLine>> read_pose_lines(const std::string& path) {
  Result<std::string> text = read_text_file(path, kMaxPoseFileBytes, "pose file");
  if (!text) return Error{text.error()};
  return parse_pose_lines(text.value(), path);
}

Result<std::vector<Pose>> read_poses(const std::string& path) { return poses_only(read_pose_lines(path)); }

std::string format_pose(const Pose& pose) {
  std::string out;
  char buf[32];
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      const auto res = std::to_chars(buf, buf + sizeof buf, pose.matrix()(r, c));
      if (!out.empty()) out += ' ';
      out.append(buf, res.ptr);
    }
  return out;
}

}  // namespace st::geom
