// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Point location on one body's surface seen along a direction (the patch contact model's exit
/// distances: the depth search, the held contact). Internal to src/spheretouch/geom; the patch model is in
/// contact_patch.hpp.
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>

#include <spheretouch/geom/contact.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Point location on one body's surface seen along a direction d: walks from a start face across
/// edges (Guibas & Stolfi's walk) over the faces that face d, to the face above a point, and
/// answers how far the point must travel along d to leave through it.
struct SurfaceWalk {
  const Mesh* mesh = nullptr;              ///< the surface's body
  const VertexFaces* vf = nullptr;         ///< its faces around each vertex
  ContactBuilder::Patch* patch = nullptr;  ///< set when the surface is the probe (vertices move with the pose)
  ///@{
  Vec3 d{Vec3::UnitZ()}, u{Vec3::UnitX()}, w{Vec3::UnitY()};  ///< direction and the plane ⊥ d
  ///@}
  /// Sets the direction (unit) and derives the plane basis.
  void set_direction(const Vec3& dir);
  /// The walk's test that a face (a, b, c) faces d, from det = its projected area's orientation
  /// ((b−a)×(c−a)·d): turned less than acos(kFrontCos) from d.
  static bool facing(double det, const Vec3& a, const Vec3& b, const Vec3& c);
  /// Vertex v in the common frame.
  Vec3 at(std::uint32_t v);
  /// Walks from `face` to the face above (or below) x seen along d; on success `face` is that
  /// face and `dist` how far x must travel along d to reach it (<= 0: x is outside, above it).
  /// False when the walk would leave the faces that face d, or takes more than max_steps.
  /// `last`, when given, is the last face walked (that faces d), also when the walk fails.
  bool exit(const Vec3& x, std::uint32_t& face, double& dist, int max_steps = 48, std::uint32_t* last = nullptr);
  /// Whether x, seen along d, lies within `margin` of face f; if so `dist` is how far x must
  /// travel along d to reach f's plane.
  bool near_face(const Vec3& x, std::uint32_t f, double margin, double& dist);
  /// The face across edge (a, b) of face f, or UINT32_MAX.
  std::uint32_t across(std::uint32_t f, std::uint32_t a, std::uint32_t b) const;
};

}  // namespace st::geom
