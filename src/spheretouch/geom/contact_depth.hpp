// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The patch contact model's depth search: one side's directional penetration depth along FD (Kim,
/// Lin & Manocha 2002, on the contact patch only), the deepest of one body's points inside the
/// other found by steepest-ascent climbs over its vertices, then refined where edges cross.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <limits>
#include <vector>

#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/surface_walk.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

struct PatchBody;  // contact_patch.hpp

/// What one side remembers between rounds: its deepest vertex and the face it left through
/// (the next round's climb starts there).
struct DepthMemory {
  static constexpr int kSize = 4;   ///< local maxima remembered (separate contact regions)
  static constexpr int kKnown = 8;  ///< vertices known to lie in followed regions (see `known`)
  std::uint32_t vertex[kSize] = {UINT32_MAX, UINT32_MAX, UINT32_MAX, UINT32_MAX};  ///< maxima, deepest first
  std::uint32_t face[kSize] = {UINT32_MAX, UINT32_MAX, UINT32_MAX, UINT32_MAX};    ///< the faces they left through
  /// Vertices whose regions count as followed when groups' extents are checked (a search after
  /// a remembered maximum was lost), from the last search that climbed from new regions: local
  /// maxima it found beyond the kSize deepest (not climbed each round), and a vertex of each
  /// group it climbed from (a region is new once: else a patch with more than kSize peaks, or a
  /// rim around a hole, would be searched every time).
  std::uint32_t known[kKnown] = {UINT32_MAX, UINT32_MAX, UINT32_MAX, UINT32_MAX,
                                 UINT32_MAX, UINT32_MAX, UINT32_MAX, UINT32_MAX};
  ///@{
  /// The patrol's climb (see DepthSearch): the vertex it stopped at (UINT32_MAX: none under
  /// way), the face that vertex left through, and how many climbs it has started.
  std::uint32_t patrol = UINT32_MAX, patrol_face = UINT32_MAX, patrol_k = 0;
  ///@}
  /// A remembered maximum was lost (no longer inside) since the last search for new regions:
  /// its region may have no maximum followed any more.
  bool lost = false;
};

/// Result of one side's depth search.
struct Deepest {
  double depth = 0;                   ///< largest exit distance found, mm (0: none inside)
  std::uint32_t vertex = UINT32_MAX;  ///< the vertex it belongs to (UINT32_MAX: an edge point)
  Vec3 point{Vec3::Zero()};           ///< the deepest point, common (object-local) frame
  std::uint32_t face = UINT32_MAX;    ///< the surface face it leaves through
  std::uint32_t inside = 0;           ///< vertices found inside
  bool capped = false;                ///< the search stopped at max_inside_vertices
};

/// One side's depth search in a round of the patch model: the points of the `test` body inside
/// the `surface` body and how far each must travel along d to leave (an exit distance, found by
/// a SurfaceWalk over the surface's faces that face d). The deepest is found by steepest-ascent
/// climbs over the test body's vertices: from last round's local maxima (the body's DepthMemory),
/// from the colliding pairs of regions not followed yet (every kDiscoverEvery rounds, or when
/// nothing is remembered), and a patrol over the whole patch; then between vertices, where the
/// test body's edges cross the surface's edges seen along d. Runs once per side and round, after
/// the patch's pairs and records (ContactBuilder::Patch::build()).
class DepthSearch {
 public:
  /// The probe's points inside the object leaving along d (probe_side), or the object's inside
  /// the probe leaving along d; d unit, object-local.
  DepthSearch(ContactBuilder::Patch& patch, bool probe_side, const Vec3& d);
  /// Runs the search (once) and updates the test body's memory for the next round.
  Deepest run();

 private:
  /// A surface face seen along d: its corners in the plane ⊥ d and their heights.
  struct Seen {
    std::uint32_t face;
    double pu[3], pw[3], ph[3];
  };
  // The steps of run() and their helpers (once the lambdas of one long function), defined and
  // used in contact_depth.cpp only; inline, so that the compiler may inline them into the climbs
  // as it did the lambdas.
  inline Vec3 test_pos(std::uint32_t v);                    ///< vertex v of the test body, object-local
  inline double eval(std::uint32_t v, std::uint32_t hint);  ///< v's exit distance (−∞: none), once a round
  inline void drop(std::uint32_t v);                        ///< v's region counts as followed next time
  inline void remember(std::uint32_t v);                    ///< keeps a local maximum, deepest first
  /// Climbs from v to a local maximum (or an earlier climb's path); where it stopped after
  /// max_steps steps, UINT32_MAX when it ended.
  inline std::uint32_t climb_from(std::uint32_t v, int max_steps = std::numeric_limits<int>::max());
  inline bool climb_remembered(bool discover_round);  ///< climbs from last round's maxima
  inline void open_pairs(bool discover, bool full);   ///< the pairs a search for new regions starts from
  inline std::uint32_t group_regions();               ///< groups T's faces, marks the open groups
  inline void mark_followed(std::uint32_t n_groups);  ///< after a lost maximum: the groups none follows
  /// Whether v, seen along d, lies in a group's extent bx (u, w: uc, wc in the common frame).
  inline bool in_extent(std::uint32_t v, const double* bx, const Vec3& uc, const Vec3& wc);
  inline bool climb_from_pairs();                         ///< climbs from the open pairs
  inline void patrol(bool discover, bool full);           ///< one patrol climb, continued
  inline void keep_memory(bool discover, bool searched);  ///< T's memory for the next round
  inline bool see(std::uint32_t f, Seen& sn);             ///< surface face f seen along d
  /// Where test edge (ia, ib) crosses the edges of the seen faces along d.
  inline void refine_edge(std::uint32_t ia, std::uint32_t ib, const Seen* seen, int n_seen);
  /// Whether a point below edge (e, e+1) of a seen face, along d, lies inside S there: the face
  /// across that edge faces d too, or the edge is concave (a point under a convex silhouette edge
  /// is outside S, however deep the crossing looks).
  bool inside_below_edge(const Seen& sn, int e);
  inline void refine_around(std::uint32_t c);              ///< edge crossings around vertex c
  inline void follow_ridge(std::uint32_t deepest_vertex);  ///< crossings from fan to fan along a ridge
  inline void refine_pairs();                              ///< crossings over every colliding pair

  ContactBuilder::Patch& patch_;       ///< the round
  const bool probe_side_;              ///< the test body is the probe
  PatchBody& T_;                       ///< the body whose points may be inside (test)
  PatchBody& S_;                       ///< the body whose faces they leave through (surface)
  const Mesh& test_;                   ///< T's mesh
  const Mesh& surface_;                ///< S's mesh
  const VertexFaces& test_vf_;         ///< T's faces around each vertex
  const std::size_t test_nv_;          ///< T's vertex count
  const std::uint32_t epoch_;          ///< the round's stamp
  const Vec3 d_;                       ///< the exit direction, unit, object-local
  std::vector<std::uint32_t>& visit_;  ///< T's visit stamps
  std::vector<double>& depth_;         ///< T's per-vertex exit distances this round
  std::vector<std::uint32_t>& exitf_;  ///< and the faces they were found on
  std::vector<std::uint32_t>& path_;   ///< T's path stamps
  DepthMemory& memory_;                ///< T's memory

  SurfaceWalk walk_;               ///< over S's faces that face d
  Deepest best_;                   ///< the deepest point so far
  std::uint32_t evaluated_ = 0;    ///< exit distances looked for (max_inside_vertices)
  std::uint32_t round_first_ = 0;  ///< the first climb serial of this search (0: not run)

  std::uint32_t maxima_[DepthMemory::kSize];  ///< local maxima found, deepest first
  double maxima_depth_[DepthMemory::kSize];   ///< and their depths
  int n_maxima_ = 0;                          ///< maxima kept
  std::uint32_t known_[DepthMemory::kKnown];  ///< known for the next searches for new regions
  int n_known_ = 0;                           ///< known kept
  bool lost_ = false;                         ///< a remembered maximum was lost since the last search

  std::uint32_t won_a_ = UINT32_MAX, won_b_ = UINT32_MAX;  ///< the test edge whose crossing won last
};

}  // namespace st::geom
