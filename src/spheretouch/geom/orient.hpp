// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// orient_faces(): makes a mesh's winding what the contact models read it as (Mesh::faces:
/// counter-clockwise seen from outside). The force direction comes from the faces' orientation
/// (the patch model's vector area, the paper model's face normals): a face wound the other way
/// pulls the probe into the object instead of pushing it out. Files often have such faces: an
/// exporter that writes clockwise, a mirrored part, a few facets flipped by a repair tool.
//
// How. Faces are joined across their manifold edges (exactly two faces use the edge; corners at
// one position are one corner, coincident_vertices(), so a soup is joined as welded); a walk
// over each edge-connected part flips every face whose winding disagrees with the face it was
// reached from (two faces of an oriented surface traverse their shared edge in opposite
// directions). Then each part is turned as a whole:
//  * a closed part (no edge it uses once: an edge shared with other parts, used twice by each
//    of two cubes that meet along it, leaves both closed) faces out of the material: outward
//    (positive signed volume) when it lies inside an even number of the other closed parts,
//    inward when odd (the wall of a cavity, the inner shell of a hollow ball). A part lies inside
//    another when its bounds do and so do up to 16 of its vertices (its extremes along each axis
//    and others spread over it), each by its winding number about the other part (the sum of its
//    faces' signed solid angles); closed parts that overlap without one holding the other (an
//    assembly's parts pushed into each other) are each wound outward.
//  * an open part (a sheet, a plate modelled by one surface, a soup) has no inside: it keeps the
//    winding the larger area of its faces had in the file (a contact with it takes the side the
//    probe comes from: contact.hpp).
// Edges used by three or more faces join nothing (which way round is ambiguous there), so parts
// that meet only along such edges are oriented each on its own. A part that cannot be oriented
// (a Möbius strip) keeps what the walk gave it, and its disagreeing edges are counted.
// No face is renumbered and no vertex moves: a flipped face swaps its last two corners.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <spheretouch/geom/mesh.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// What orient_faces() did.
struct OrientReport {
  std::size_t flipped = 0;         ///< faces whose winding was reversed
  std::size_t parts = 0;           ///< edge-connected parts (across manifold edges)
  std::size_t closed_parts = 0;    ///< of those, closed (no edge used once by the part) with a volume
  std::size_t inverted_parts = 0;  ///< closed parts that were inside out (most of their area flipped here)
  std::size_t cavities = 0;        ///< closed parts inside an odd number of others (wound inward)
  std::size_t unorientable_edges = 0;  ///< manifold edges still traversed the same way by both faces (a non-orientable part)
  /// Closed parts whose nesting was not decided (too many face tests: see kMaxNestingTests);
  /// they are wound outward.
  std::size_t nesting_skipped = 0;
};

/// Bound on the face visits the nesting test may make (winding numbers of up to 16 vertices per
/// closed part about the closed parts whose bounds hold its bounds): beyond it the remaining parts
/// are wound outward. Only meshes of many closed parts inside each other's bounds come near it.
inline constexpr std::size_t kMaxNestingTests = std::size_t(1) << 26;

/// Makes the winding of `mesh` consistent across each part and outward (header comment).
/// Deterministic; O(F log F) plus the nesting test.
OrientReport orient_faces(Mesh& mesh);

/// Per face, 1 when it lies in an open part (as orient_faces() finds the parts) and is not a
/// point: no inside, so the patch model lets a contact take the side the probe comes from
/// (contact.hpp).
std::vector<std::uint8_t> open_part_faces(const Mesh& mesh);

/// One line for a user on what orient_faces() changed ("12 faces flipped to wind consistently and
/// outward (1 closed part was inside out)"), the open parts (no inside) and what it could not
/// decide; empty when it changed nothing and every part is closed.
std::string describe_winding(const OrientReport& report);

}  // namespace st::geom
