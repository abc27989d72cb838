// Pose file reading and writing. Numbers go through std::from_chars / std::to_chars: correctly
// rounded, locale-independent, and shortest-round-trip on output, so a written pose reads back
// bit for bit.
#include "geom/pose_io.hpp"

#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace st::geom {
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

/// Checks 16 parsed values as a rigid transform; an empty string when it is one.
std::string check_rigid(const std::array<double, kValues>& v) {
  if (v[12] != 0.0 || v[13] != 0.0 || v[14] != 0.0 || v[15] != 1.0)
    return "last row must be 0 0 0 1, found " + join_values(&v[12], 4);
  Eigen::Matrix3d r;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r(i, j) = v[4 * i + j];
  const double err = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(err <= kPoseOrthonormalTolerance)) {
    std::ostringstream os;
    os << "rotation block is not orthonormal: max |R^T R - I| entry is " << err << " > "
       << kPoseOrthonormalTolerance;
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

}  // namespace

Result<std::vector<Pose>> parse_poses(std::string_view text, std::string_view name) {
  std::vector<Pose> poses;
  std::size_t line_no = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    ++line_no;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos)
      line = line.substr(0, hash);

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
        return fail(name, ":", line_no, ": value ", count + 1, " (column ", i + 1, ") '", tok,
                    "' ", why);
      if (!std::isfinite(x))
        return fail(name, ":", line_no, ": value ", count + 1, " (column ", i + 1, ") '", tok,
                    "' is not finite");
      if (count < kValues) v[count] = x;
      ++count;
      i = j;
    }
    if (count == 0) continue;  // blank or comment-only line
    if (count != kValues)
      return fail(name, ":", line_no, ": expected ", kValues,
                  " numbers (a row-major 4x4 rigid transform), found ", count);
    if (const std::string why = check_rigid(v); !why.empty())
      return fail(name, ":", line_no, ": ", why);
    Pose pose = Pose::Identity();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) pose.matrix()(r, c) = v[4 * r + c];
    poses.push_back(pose);
  }
  if (poses.empty()) return fail(name, ": no poses (the file is empty or has only comments)");
  return poses;
}

Result<std::vector<Pose>> read_poses(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return fail(path, ": is a directory, not a pose file");
  std::ifstream in(path, std::ios::binary);
  if (!in) return fail(path, ": cannot open pose file: ", std::strerror(errno));
  std::ostringstream buf;
  buf << in.rdbuf();
  if (in.bad()) return fail(path, ": read error: ", std::strerror(errno));
  return parse_poses(buf.str(), path);
}

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
