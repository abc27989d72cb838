// SPDX-License-Identifier: BSD-3-Clause
// Shared pieces of the harness benchmarks (bench_tables.cpp, bench_trade.cpp): body
// loading (files or the built-in ~960-face icosphere), pose files with their "# contacts N
// (target T)" comments, the hand's built-in press/slide script, worker daemons over tcp
// loopback, percentiles and CSV appending.
#pragma once
#include <sys/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/rt/simulated_device.hpp>

namespace st::bench {

/// A body with its sphere tree.
struct Body {
  std::string label;      ///< file stem or "icosphere"
  geom::Mesh mesh;        ///< the mesh
  geom::SphereTree tree;  ///< its layered spheres
};

/// Loads a mesh file, or generates "icosphere[:RADIUS_MM[:FREQUENCY]]" (default 50 mm, 7 → 980
/// faces: the paper's ~960-face ball), and builds its tree. Exits (CLI error) on failure.
Body load_body(const std::string& spec, std::uint32_t leaf_faces = geom::DefaultTreeConfig().leaf_faces);

/// One pose of a pose file, with the contact count and target of its "# contacts N (target T)"
/// comment (0 when absent).
struct TaggedPose {
  geom::Pose pose;
  std::uint32_t contacts = 0, target = 0;
};
/// Reads a pose file (geom::read_pose_lines: checked) with its "# contacts N (target T)" tags. Exits on an error.
std::vector<TaggedPose> read_tagged_poses(const std::string& path);

/// The built-in approach/press/slide/release script (rt::builtin_press_slide) moving the probe's
/// lowest vertex along -z onto the object's highest vertex along +z, identity orientation, time
/// scaled to last `duration_s` (the unscaled script takes 5 s).
rt::Trajectory press_slide_script(const geom::Mesh& probe, const geom::Mesh& object, double duration_s,
                                  double press_mm = 3.0, double slide_mm = 20.0);

/// `n` spheretouch-worker processes on free tcp loopback ports; SIGTERM and reaped on destruction.
class Daemons {
 public:
  Daemons(const std::string& binary, int n);
  ~Daemons();
  Daemons(const Daemons&) = delete;
  Daemons& operator=(const Daemons&) = delete;
  const std::vector<std::string>& endpoints() const { return endpoints_; }  ///< tcp://127.0.0.1:PORT

 private:
  std::vector<pid_t> pids_;
  std::vector<std::string> endpoints_;
};

/// q-quantile (0..1) of v by nearest rank; 0 for an empty vector. Sorts v.
double quantile(std::vector<double>& v, double q);
/// Appends `row` to the CSV file, writing `header` first when the file is new or empty.
void append_csv(const std::string& path, const std::string& header, const std::string& row);
/// Splits "1,2,4" into integers (empty tokens skipped); a token that is not an integer is a
/// CLI::ValidationError naming `option` and the token.
std::vector<int> parse_int_list(const std::string& s, const std::string& option);
/// Splits "0.01,0.1" into positive finite numbers (empty tokens skipped); anything else is a
/// CLI::ValidationError naming `option` and the token.
std::vector<double> parse_positive_list(const std::string& s, const std::string& option);
/// File stem of a path ("a/b/hand_L2.off" -> "hand_L2").
std::string stem(const std::string& path);
/// Heap bytes of a mesh's vertex and face arrays.
std::size_t mesh_bytes(const geom::Mesh& m);

}  // namespace st::bench
