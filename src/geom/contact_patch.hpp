// The patch contact model's state and scratch (ContactBuilder::Patch); the model is defined in
// contact.hpp. Internal to src/geom: contact.cpp owns one per builder.
#pragma once
#include <cstdint>
#include <span>
#include <vector>

#include "geom/contact.hpp"

namespace st::geom {

/// Unit normal and centroid of face f of m, m's local frame; false when degenerate or non-finite.
bool face_frame(const Mesh& m, std::uint32_t f, Vec3& centroid, Vec3& normal);

/// A height field over the faces of one side that face a direction d: faces projected on the
/// plane ⊥ d, binned in a uniform 2D grid. exit() answers how far a point must travel along d to
/// leave through the nearest of them. Reused between rounds (no allocation once warm).
class HeightField {
 public:
  /// One face: 2D corners (u, w) and the heights along d of its corners.
  struct Face {
    double u[3], w[3], h[3];
    std::uint32_t id;  ///< face index in its mesh
  };
  /// Starts a new field for direction d (unit): basis vectors are derived from it.
  void begin(const Vec3& d);
  /// Adds a triangle (corners in the common frame) whose normal faces d.
  void add(const Vec3& a, const Vec3& b, const Vec3& c, std::uint32_t id);
  /// Bins the faces; call after the last add().
  void finish();
  /// Distance along d from x to the nearest face above it (> 0), or -1 when no face is above x.
  /// `face` receives the face's id.
  double exit(const Vec3& x, std::uint32_t& face) const;
  /// The most an exit distance grows where segment a–b (the other side's edge) crosses this
  /// field's face edges, seen along d: returns the largest exit() at those crossings (-1: none)
  /// and the crossing point in `at`.
  double refine(const Vec3& a, const Vec3& b, Vec3& at, std::uint32_t& face) const;
  /// x projected on the plane ⊥ d: (u, w).
  void project(const Vec3& x, double& u, double& w) const { u = x.dot(u_), w = x.dot(w_); }
  bool empty() const { return faces_.empty(); }  ///< no face added
  std::size_t size() const { return faces_.size(); }  ///< faces added
  std::size_t bytes() const;  ///< scratch held

 private:
  Vec3 d_{Vec3::UnitZ()}, u_{Vec3::UnitX()}, w_{Vec3::UnitY()};
  std::vector<Face> faces_;
  double lo_u_ = 0, lo_w_ = 0, inv_cell_ = 1;
  int nu_ = 1, nw_ = 1;
  std::vector<std::uint32_t> cell_start_, cell_faces_, scratch_fill_;
};

/// ContactBuilder's patch model (see contact.hpp for what it computes).
struct ContactBuilder::Patch {
  explicit Patch(const ContactConfig& c) : config(c) {}
  void prepare(const Mesh& probe, const Mesh& object);
  ContactModel build(const Mesh& probe, const Mesh& object, const Pose& pose, std::span<const ContactPair> pairs);
  void reset();
  bool has_history() const { return have_prev; }
  std::size_t bytes() const;

  /// Result of one side's flood fill.
  struct Deepest {
    double depth = 0;                 ///< largest exit distance found, mm (0: none inside)
    std::uint32_t vertex = UINT32_MAX;  ///< the vertex it belongs to (UINT32_MAX: an edge point)
    Vec3 point{Vec3::Zero()};         ///< the deepest point, common (object-local) frame
    std::uint32_t face = UINT32_MAX;  ///< the surface face it leaves through
    std::uint32_t inside = 0;         ///< vertices found inside
    bool capped = false;              ///< a fill stopped at max_inside_vertices
  };
  /// One side's pass: points of `test` inside `surface`, leaving along d.
  Deepest side(bool probe_side, const Vec3& d, const Mesh& probe, const Mesh& object);

  ContactConfig config;
  // Per-mesh data (prepare()).
  const Mesh* probe_mesh = nullptr;
  const Mesh* object_mesh = nullptr;
  std::size_t probe_nv = 0, probe_nf = 0, object_nv = 0, object_nf = 0;
  VertexFaces probe_vf, object_vf;
  // History.
  bool have_prev = false;                 ///< prev_n is the last model's FD
  Vec3 prev_n{Vec3::Zero()};
  bool held_valid = false;                ///< a contact plane to hold
  Vec3 held_n{Vec3::Zero()};              ///< its normal
  Vec3 held_point{Vec3::Zero()};          ///< a point of it, object-local, mm
  Vec3 held_tracked{Vec3::Zero()};        ///< the probe point held against it, probe-local, mm
  double held_radius = 0;                 ///< the patch footprint around held_point, mm
  // Scratch.
  std::vector<ContactPair> valid;
  std::vector<std::uint32_t> probe_faces, object_faces, queue;
  std::vector<Vec3> probe_world;          ///< probe vertices, object-local (valid where stamped)
  std::vector<Vec3> curve;                ///< intersection segment end points, object-local
  std::vector<std::uint32_t> probe_xform_stamp, probe_visit_stamp, object_visit_stamp;
  std::vector<std::uint32_t> probe_face_stamp, object_face_stamp;
  Eigen::Matrix3d rot{Eigen::Matrix3d::Identity()};  ///< this round's pose rotation
  Vec3 shift{Vec3::Zero()};               ///< and translation, probe-local → object-local
  const Vec3& probe_point(std::uint32_t v, const Mesh& probe);  ///< probe vertex v, object-local
  std::uint32_t epoch = 0;
  HeightField field;
};

}  // namespace st::geom
