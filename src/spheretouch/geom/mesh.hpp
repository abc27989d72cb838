// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Mesh: indexed triangles of one rigid body.
/// Frames, one name each, used by every header:
///  * the body's frame ("object frame", "probe frame"): the coordinates of its mesh file, mm.
///    A pose maps the probe frame into the object frame.
///  * the body's local frame: its frame shifted by `origin` (the body's centre, kept in double).
///    Vertices are stored in it so a body placed 10^6 mm from the origin keeps full precision;
///    large offsets live only in poses and origins. Trees and collide()'s caches use it.
///  * the world frame: where the public API's Body::frame() places a body (spheretouch/collide.hpp).
#pragma once
#include <spheretouch/abi.hpp>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <bit>
#include <cstdint>
#include <string>
#include <vector>

#include <spheretouch/geom/result.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

using Vec3 = Eigen::Vector3d;              ///< point or vector, double precision, mm
using Pose = Eigen::Isometry3d;            ///< rigid transform, double precision, mm
using Tri = std::array<std::uint32_t, 3>;  ///< a face's vertex indices

/// Axis-aligned box in double precision.
struct Box {
  Vec3 lo{Vec3::Constant(std::numeric_limits<double>::infinity())};   ///< minimum corner
  Vec3 hi{Vec3::Constant(-std::numeric_limits<double>::infinity())};  ///< maximum corner
  void grow(const Vec3& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }                                                                     ///< include a point
  bool empty() const { return !(lo.x() <= hi.x()); }                    ///< no point yet
  Vec3 centre() const { return 0.5 * (lo + hi); }                       ///< midpoint
  double diagonal() const { return empty() ? 0.0 : (hi - lo).norm(); }  ///< length of the diagonal, mm
};

/// Edge-topology facts about a mesh, computed by Mesh::topology().
struct Topology {
  std::size_t boundary_edges = 0;     ///< edges used by exactly one face (open surface)
  std::size_t nonmanifold_edges = 0;  ///< edges used by three or more faces
  std::size_t misoriented_edges = 0;  ///< manifold edges whose two faces traverse them the same way
  std::size_t shared_corners = 0;     ///< vertices at the position of a lower-numbered one (coincident_vertices())
  bool closed() const { return boundary_edges == 0; }                                 ///< watertight
  bool manifold() const { return nonmanifold_edges == 0 && misoriented_edges == 0; }  ///< 2-manifold, oriented
};

/// Indexed triangle mesh of one body. Face index = position in the input file.
struct Mesh {
  std::string name;           ///< where it came from (file path or generator), for messages
  Vec3 origin{Vec3::Zero()};  ///< body centre in the body's frame, mm
  std::vector<Vec3> local;    ///< vertex positions relative to origin, mm
  std::vector<Tri> faces;     ///< vertex indices, counter-clockwise seen from outside

  std::size_t num_faces() const { return faces.size(); }            ///< triangle count
  std::size_t num_vertices() const { return local.size(); }         ///< vertex count
  Vec3 vertex(std::uint32_t i) const { return origin + local[i]; }  ///< position in the body's frame
  Box local_bounds() const;                                         ///< bounds of `local`
  Box bounds() const;                                               ///< bounds in the body's frame
  Topology topology() const;  ///< edge counts, corners joined as coincident_vertices() joins them (O(F log F))
  std::vector<std::uint32_t> degenerate_faces() const;  ///< zero-area faces, ascending
  /// Re-centres the body: origin becomes the bounding-box centre, snapped so that subtracting it
  /// from every vertex is exact where the coordinates allow (see mesh.cpp).
  void recentre();
  /// Multiplies every coordinate (and the origin) by s; the frame's centre stays the origin's image.
  void scale(double s);
  /// Checks indices and coordinates; the error names the first bad face or vertex.
  Status validate() const;
};

/// Per vertex, the lowest index of a vertex at the same position (itself when it has none;
/// -0 and +0 are the same, a non-finite vertex has none). A file written as three corners per
/// triangle (a soup: PLY and OFF are read as written) or split at its seams (normals, texture
/// coordinates) holds one corner of the surface several times; what reads the surface's
/// connectivity (topology(), orient_faces(), the patch contact model) joins faces through these.
/// O(V log V).
std::vector<std::uint32_t> coincident_vertices(const Mesh& mesh);

/// Word-wise multiply-rotate hash with a final avalanche (not cryptographic: it tells a changed
/// mesh or a stale cache file, not a forged one).
class WordHash {
 public:
  explicit WordHash(std::uint64_t seed) : h_(seed) {}  ///< starts from `seed`
  /// Mixes in one 64-bit word.
  void word(std::uint64_t w) {
    h_ ^= w * 0x87c37b91114253d5ull;
    h_ = std::rotl(h_, 31) * 0x4cf5ad432745937full + 0x52dce729ull;
  }
  /// Bytes as 8-byte little-endian words; the last, partial one tagged with its length.
  void bytes(const void* p, std::size_t n);
  std::uint64_t finish() const;  ///< the hash of every word so far, avalanched

 private:
  std::uint64_t h_;
};

/// A WordHash over the mesh's vertex and face counts, origin, local vertices and faces, bytes as
/// stored (tree_hash goes on from it with the build parameters).
WordHash mesh_words(const Mesh& mesh);

/// 64-bit hash of the mesh's origin, local vertices and faces (mesh_words, finished): tells
/// whether two loads gave the same mesh (`spheretouch monitor --view` checks the scene file still
/// gives the run's meshes).
std::uint64_t mesh_hash(const Mesh& mesh);

/// Builds a mesh from vertex positions in the body's frame (recentred) and faces.
Mesh make_mesh(std::string name, const std::vector<Vec3>& positions, std::vector<Tri> faces);

}  // namespace st::geom
