// SPDX-License-Identifier: BSD-3-Clause
// Tests src/spheretouch/geom/pose_io.*: the accepted syntax (comments, blank lines, CRLF, signs), every
// error message (file:line, what is wrong), and exact round trips through format_pose.
#include <spheretouch/geom/pose_io.hpp>

#include <doctest/doctest.h>
#include <filesystem>
#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <string>

#include <unistd.h>

using st::geom::format_pose;
using st::geom::parse_poses;
using st::geom::Pose;
using st::geom::read_poses;

namespace {

const char* const kIdentity = "1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1";

/// The error message of a parse that must fail (empty string if it unexpectedly succeeded).
std::string error_of(const std::string& text) {
  auto r = parse_poses(text, "p.txt");
  return r.ok() ? std::string() : r.error();
}

}  // namespace

TEST_CASE("parse_poses: accepted syntax") {
  const std::string text =
      "# header comment\n"
      "\n"
      "1 0 0 10   0 1 0 -20.5   0 0 1 3e2   0 0 0 1   # trailing comment\n"
      "   \t\n"
      "0 -1 0 +1\t1 0 0 0 0 0 1 0 0 0 0 1\r\n"  // tab, '+' sign, CRLF
      "0 0 1 0 0 1 0 0 -1 0 0 0 0 0 0 1";       // no final newline
  auto r = parse_poses(text, "p.txt");
  REQUIRE(r.ok());
  const auto& poses = r.value();
  REQUIRE(poses.size() == 3);
  CHECK(poses[0].translation() == Eigen::Vector3d(10, -20.5, 300));
  CHECK(poses[0].linear() == Eigen::Matrix3d::Identity());
  CHECK(poses[1].translation() == Eigen::Vector3d(1, 0, 0));
  CHECK(poses[1] * Eigen::Vector3d(1, 0, 0) == Eigen::Vector3d(1, 1, 0));  // 90° about z
  CHECK(poses[2].linear().determinant() == doctest::Approx(1.0).epsilon(1e-15));
}

TEST_CASE("parse_poses: rotation tolerance boundary") {
  // Off-diagonal RᵀR entries grow linearly with a small shear s: accept 1e-8, reject 1e-5.
  CHECK(parse_poses("1 1e-8 0 0  0 1 0 0  0 0 1 0  0 0 0 1", "p").ok());
  CHECK(error_of("1 1e-5 0 0  0 1 0 0  0 0 1 0  0 0 0 1") ==
        "p.txt:1: rotation block is not orthonormal: max |R^T R - I| entry is 1e-05 > 1e-06");
  // A rotation printed with 7 significant digits is accepted as written, not re-orthonormalised.
  const double c = std::cos(0.3), s = std::sin(0.3);
  char line[256];
  std::snprintf(line, sizeof line, "%.7g %.7g 0 0 %.7g %.7g 0 0 0 0 1 0 0 0 0 1", c, -s, s, c);
  auto r = parse_poses(line, "p");
  REQUIRE(r.ok());
  char cos7[32];
  std::snprintf(cos7, sizeof cos7, "%.7g", c);
  CHECK(r.value()[0].matrix()(0, 0) == std::strtod(cos7, nullptr));
}

TEST_CASE("parse_poses: every error names file:line and what is wrong") {
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0") ==
        "p.txt:1: expected 16 numbers (a row-major 4x4 rigid transform), found 15");
  CHECK(error_of(std::string(kIdentity) + "\n" + kIdentity + " 7\n") ==
        "p.txt:2: expected 16 numbers (a row-major 4x4 rigid transform), found 17");
  CHECK(error_of("# c\n\n1 0 0 x 0 1 0 0 0 0 1 0 0 0 0 1\n") == "p.txt:3: value 4 (column 7) 'x' is not a number");
  CHECK(error_of("1,0,0,0 0 1 0 0 0 0 1 0 0 0 0 1") == "p.txt:1: value 1 (column 1) '1,0,0,0' is not a number");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1.0.0") == "p.txt:1: value 16 (column 31) '1.0.0' is not a number");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 +-1") == "p.txt:1: value 16 (column 31) '+-1' is not a number");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 0x10 0 0 0 1") == "p.txt:1: value 12 (column 23) '0x10' is not a number");
  CHECK(error_of("1 0 0 nan 0 1 0 0 0 0 1 0 0 0 0 1") == "p.txt:1: value 4 (column 7) 'nan' is not finite");
  CHECK(error_of("1 0 0 0 0 1 0 -inf 0 0 1 0 0 0 0 1") == "p.txt:1: value 8 (column 15) '-inf' is not finite");
  CHECK(error_of("1 0 0 1e999 0 1 0 0 0 0 1 0 0 0 0 1") ==
        "p.txt:1: value 4 (column 7) '1e999' is out of the range of a double");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 1e-400 0 0 0 1") ==
        "p.txt:1: value 12 (column 23) '1e-400' is out of the range of a double");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 1e 0 0 0 1") == "p.txt:1: value 12 (column 23) '1e' is not a number");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0.5 1") == "p.txt:1: last row must be 0 0 0 1, found 0 0 0.5 1");
  CHECK(error_of("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 2") == "p.txt:1: last row must be 0 0 0 1, found 0 0 0 2");
  CHECK(error_of("2 0 0 0 0 2 0 0 0 0 2 0 0 0 0 1") ==
        "p.txt:1: rotation block is not orthonormal: max |R^T R - I| entry is 3 > 1e-06");
  CHECK(error_of("-1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1") ==
        "p.txt:1: rotation block is not a rotation (reflection): det = -1");
  CHECK(error_of("0 1 0 0 1 0 0 0 0 0 1 0 0 0 0 1") ==
        "p.txt:1: rotation block is not a rotation (reflection): det = -1");
  CHECK(error_of("") == "p.txt: no poses (the file is empty or has only comments)");
  CHECK(error_of("# only\n\n   # comments\n") == "p.txt: no poses (the file is empty or has only comments)");
}

TEST_CASE("read_poses: files") {
  const std::string path = "/tmp/st_pose_io_test_" + std::to_string(::getpid()) + ".txt";
  {
    std::ofstream out(path);
    out << "# two poses\n" << kIdentity << "\n0 0 1 5 1 0 0 6 0 1 0 7 0 0 0 1\n";
  }
  auto r = read_poses(path);
  REQUIRE(r.ok());
  CHECK(r.value().size() == 2);
  CHECK(r.value()[1].translation() == Eigen::Vector3d(5, 6, 7));
  {
    std::ofstream out(path);
    out << kIdentity << "\n\n1 2 3\n";
  }
  auto bad = read_poses(path);
  REQUIRE_FALSE(bad.ok());
  CHECK(bad.error() == path + ":3: expected 16 numbers (a row-major 4x4 rigid transform), found 3");
  std::remove(path.c_str());

  auto missing = read_poses("/nonexistent/dir/poses.txt");
  REQUIRE_FALSE(missing.ok());
  CHECK(missing.error() == "/nonexistent/dir/poses.txt: cannot open pose file: No such file or directory");
  auto dir = read_poses("/tmp");
  REQUIRE_FALSE(dir.ok());
  CHECK(dir.error() == "/tmp: is a directory, not a pose file");
  // /dev/zero (once read into memory until it aborted at 2.6 GB) and a FIFO nobody writes (once a
  // hang) are refused before anything is read; so is a file over the limit.
  auto zero = read_poses("/dev/zero");
  REQUIRE_FALSE(zero.ok());
  CHECK(zero.error() == "/dev/zero: not a regular file (a pose file is a text file)");
  const std::string fifo = "/tmp/st_pose_fifo_" + std::to_string(::getpid());
  std::remove(fifo.c_str());
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  auto f = read_poses(fifo);
  REQUIRE_FALSE(f.ok());
  CHECK(f.error() == fifo + ": not a regular file (a pose file is a text file)");
  std::remove(fifo.c_str());
  const std::string big = "/tmp/st_pose_big_" + std::to_string(::getpid());
  { std::ofstream o(big); }
  std::filesystem::resize_file(big, st::geom::kMaxPoseFileBytes + 1);  // sparse: nothing written
  auto b = read_poses(big);
  REQUIRE_FALSE(b.ok());
  CHECK(b.error().find("-byte limit for a pose file") != std::string::npos);
  std::remove(big.c_str());
}

TEST_CASE("format_pose: exact round trip, shortest form") {
  CHECK(format_pose(Pose::Identity()) == "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1");
  Pose t = Pose::Identity();
  t.translation() = Eigen::Vector3d(0.1, -1e6, 1e-300);
  CHECK(format_pose(t) == "1 0 0 0.1 0 1 0 -1e+06 0 0 1 1e-300 0 0 0 1");

  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::string file;
  std::vector<Pose> poses;
  for (int i = 0; i < 1000; ++i) {
    Pose p = Pose::Identity();
    p.linear() = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    p.translation() = Eigen::Vector3d(u(rng), u(rng), u(rng)) * std::pow(10.0, int(rng() % 13) - 6);
    if (i == 0) {  // signed zeros survive too
      p = Pose::Identity();
      p.matrix()(0, 1) = -0.0;
      p.translation().x() = -0.0;
    }
    poses.push_back(p);
    file += format_pose(p) + "\n";
  }
  auto r = parse_poses(file, "roundtrip");
  REQUIRE(r.ok());
  REQUIRE(r.value().size() == poses.size());
  int exact = 0;
  for (std::size_t i = 0; i < poses.size(); ++i)
    exact += std::memcmp(r.value()[i].matrix().data(), poses[i].matrix().data(), 16 * sizeof(double)) == 0;
  CHECK(exact == int(poses.size()));
  CHECK(std::signbit(r.value()[0].matrix()(0, 1)));
  CHECK(std::signbit(r.value()[0].translation().x()));
}
