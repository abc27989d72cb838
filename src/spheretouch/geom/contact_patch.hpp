// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The patch contact model's state and scratch (ContactBuilder::Patch) and its per-body state
/// (PatchBody); the model is defined in contact.hpp. Internal to src/spheretouch/geom: contact.cpp owns one
/// per builder. Its parts: the segment kernel (contact_segments.hpp), the surface walk
/// (surface_walk.hpp), the contact regions (contact_regions.hpp), the depth search (contact_depth.hpp).
#pragma once
#include <spheretouch/abi.hpp>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact.hpp>
#include <spheretouch/geom/contact_depth.hpp>
#include <spheretouch/geom/contact_planes.hpp>
#include <spheretouch/geom/contact_regions.hpp>
#include <spheretouch/geom/contact_segments.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Unit normal and centroid of face f of m, m's local frame; false when degenerate or non-finite.
bool face_frame(const Mesh& m, std::uint32_t f, Vec3& centroid, Vec3& normal);

/// PatchBody::use: what a colliding face's record gives the segments.
inline constexpr std::uint8_t kNoDirection = 0;  ///< degenerate or bad vertex indices: no segment
inline constexpr std::uint8_t kUsable = 1;       ///< a unit normal
inline constexpr std::uint8_t kFront = 2;        ///< and (object faces) not turned away from the previous FD

/// What the patch model keeps per body: the faces around each vertex, and per-vertex and per-face
/// search state stamped with the round (nothing is cleared between rounds).
struct PatchBody {
  const Mesh* mesh = nullptr;  ///< the body it was sized for
  ///@{
  std::size_t nv = 0, nf = 0;  ///< vertex and face counts it was sized for
  ///@}
  VertexFaces vf;                          ///< faces around each vertex
  std::vector<std::uint32_t> visit_stamp;  ///< round in which a vertex's exit distance was found
  std::vector<std::uint32_t> path_stamp;   ///< serial of the climb that stood on a vertex
  std::vector<double> depth;               ///< per-vertex exit distance this round (where visited)
  std::vector<std::uint32_t> exit_face;    ///< and the face it was found on
  /// A round stamp and a slot, side by side (read together, at random).
  struct Mark {
    std::uint32_t stamp = 0;  ///< the round
    std::uint32_t slot = 0;   ///< the slot then
  };
  std::vector<Mark> face_mark;       ///< per face: the round it was counted as colliding, its index in `faces` then
  std::vector<std::uint32_t> faces;  ///< distinct colliding faces this round (slot = index)
  std::vector<FaceRec> recs;         ///< per slot, the record moved into the common frame (when it is the other body's)
  std::vector<std::uint8_t> use;     ///< per slot: what its record gives the segments (kNoDirection, kUsable, kFront)
  /// What does not change with the pose: the face's record in its body's local frame (unit
  /// normal zero: degenerate or bad indices) and |(b−a)×(c−a)| (object faces). Kept from one
  /// round to the next (most faces collide again), so that the mesh, scattered and just swept
  /// out of the caches by the collision round, is read for new faces only; the body whose
  /// frame is the common one uses it as it is.
  struct Fixed {
    FaceRec rec;                       ///< the record, local frame
    double len = 0;                    ///< |(b−a)×(c−a)| (object faces; 0: degenerate)
    Tri vid{};                         ///< its vertex indices
    bool bad_index = false;            ///< a vertex index out of range: no record
    std::uint32_t group = UINT32_MAX;  ///< its group at the last grouping (group_faces), UINT32_MAX: none
    bool covered = false;              ///< a search for new regions has run since it began colliding
  };
  /// The fixed parts of the faces that collide this round or did the last, each in place while
  /// its face collides round after round (an entry is neither moved nor copied): entries of
  /// faces that stopped colliding are reused from the round after.
  std::vector<Fixed> store;
  std::vector<std::uint32_t> store_seen;  ///< per entry: the round its face was last counted colliding
  std::vector<std::uint32_t> store_free;  ///< entries free for new faces
  ///@{
  std::vector<std::uint32_t> entry, prev_entry;  ///< per slot: its entry, this round and the last
  ///@}
  std::vector<std::uint32_t> to_fill;  ///< slots whose entries are new this round (read from the mesh)
  /// The fixed part of this round's slot.
  Fixed& fixed(std::uint32_t slot) {
    ST_ASSERT(slot < entry.size() && entry[slot] < store.size(), "a slot of this round, settled");
    return store[entry[slot]];
  }
  /// The fixed part of this round's slot.
  const Fixed& fixed(std::uint32_t slot) const {
    ST_ASSERT(slot < entry.size() && entry[slot] < store.size(), "a slot of this round, settled");
    return store[entry[slot]];
  }
  /// Starts a round: no face counted yet (this round's entries become the last round's).
  void begin_round();
  /// Counts face f as colliding this round; returns its slot.
  inline std::uint32_t see(std::uint32_t f, std::uint32_t epoch);
  /// After the pairs: gives each slot its entry (last round's, or a new one, listed in to_fill)
  /// and frees the entries of last round's faces that do not collide this round.
  void settle(std::uint32_t epoch);
  /// Fills the entries new this round (to_fill) from the mesh.
  void fill_new();
  /// Empties the store (no face's fixed part kept).
  void clear_store();
  /// Fills fx for face f from the mesh (the unit normal from face_normals when those are kept,
  /// else computed).
  void make_fixed(Fixed& fx, std::uint32_t f) const;
  /// The round whose new entries were filled last (to_fill); 0 = none: an entry is taken over
  /// from the round before only when that round filled its entries.
  std::uint32_t fixed_epoch = 0;
  // Grouping the colliding faces into regions (a search for new regions; contact_regions.hpp):
  // group_faces after a remembered maximum was lost, else new_groups.
  std::uint32_t n_groups = 0;                ///< groups at the last grouping (Fixed::group below it)
  std::vector<std::uint32_t> group_label;    ///< per slot: its group
  std::vector<std::uint64_t> group_table;    ///< scratch: vertex → the first slot it was seen in (hash table)
  UnionFind group_sets;                      ///< scratch: union-find over the groups
  std::vector<std::uint32_t> group_remap;    ///< scratch: old or root label → new label
  std::vector<std::uint32_t> group_first;    ///< scratch: per group, its first slot
  std::vector<double> group_box;             ///< scratch: per group, its extent across d (u, w)
  std::vector<std::uint8_t> group_open;      ///< scratch: per group, a region not followed
  std::vector<std::uint8_t> group_attached;  ///< scratch (new_groups): per slot, its set touches a covered face
  std::vector<std::uint64_t> vertex_mark;    ///< scratch (new_groups): per vertex, a stamp and the face that marked it
  std::uint32_t vertex_stamp = 0;            ///< new_groups' calls so far (its stamp)
  /// Per vertex: the colliding faces around it that are covered (kept as faces are covered,
  /// cover_all, and stop colliding, settle).
  std::vector<std::uint32_t> cover_count;
  /// Marks every colliding face covered (after a search for new regions).
  void cover_all();
  std::vector<Vec3> face_normals;  ///< every face's unit normal, local frame (zero: degenerate); the probe's only
  DepthMemory memory;              ///< last round's deepest vertices (the depth search's)
  /// Whether it was sized for m (reset(m)) and m has not changed size since.
  bool sized_for(const Mesh& m) const { return mesh == &m && nv == m.local.size() && nf == m.faces.size(); }
  void reset(const Mesh& m);    ///< builds vf and sizes the state for m
  void clear_stamps();          ///< after the round counter wrapped
  void compute_face_normals();  ///< fills face_normals (once per mesh: the probe's rotate with the pose)
  std::size_t bytes() const;    ///< memory held
};

// Inlined into the pairs' loop (Patch::take_pairs), run for every colliding face: as little as
// possible besides the mark (read at random, a cache miss), so that many are in flight at once.
[[gnu::always_inline]] inline std::uint32_t PatchBody::see(std::uint32_t f, std::uint32_t epoch) {
  ST_ASSERT(f < face_mark.size(), "a face of the body");
  Mark& mark = face_mark[f];
  if (mark.stamp != epoch) {
    const bool again = fixed_epoch != 0 && fixed_epoch == epoch - 1 && mark.stamp == epoch - 1;
    entry.push_back(again ? mark.slot : UINT32_MAX);  // last round's slot for now (settle)
    mark = {epoch, static_cast<std::uint32_t>(faces.size())};
    faces.push_back(f);
  }
  return mark.slot;
}

/// ContactBuilder's patch model (see contact.hpp for what it computes).
struct ContactBuilder::Patch {
  explicit Patch(const ContactConfig& c) : config(c) {}  ///< the builder's knobs; no per-mesh data yet
  /// Sizes the per-body state for these meshes (kept while they stay the same).
  void prepare(const Mesh& probe, const Mesh& object);
  /// The model for `pairs` at `pose` (ContactBuilder::build()).
  ContactModel build(const Mesh& probe, const Mesh& object, const Pose& pose, std::span<const ContactPair> pairs);
  /// Forgets the history (as if contact had ended).
  void reset();
  /// Whether a previous FD is kept.
  bool has_history() const { return have_prev; }
  /// Memory held.
  std::size_t bytes() const;

  // build()'s steps, in order.
  /// The pairs in (probe, object) order, each once: as given when they are so, else sorted into
  /// `canonical`.
  std::span<const ContactPair> in_order(std::span<const ContactPair> pairs);
  /// Starts a round: the next epoch (every stamp cleared when it wraps).
  void next_epoch();
  /// Takes the pairs with indices in range (valid) and their faces' slots (valid_slots); fills
  /// m's face counts, and skipped_pairs with kBadInput.
  void take_pairs(const Mesh& probe, const Mesh& object, std::span<const ContactPair> pairs, ContactModel& m);
  /// This round's pose: rot and shift (probe-local → object-local, no large offsets in the sum).
  void set_pose(const Mesh& probe, const Mesh& object, const Pose& pose);
  /// The colliding object faces' normals, the fallback direction: Σ of the unnormalised normals
  /// (2 × the area-weighted mean normal) and Σ of their lengths.
  struct FaceNormals {
    Vec3 sum{Vec3::Zero()};  ///< Σ (b−a)×(c−a)
    double abs_sum = 0;      ///< Σ |(b−a)×(c−a)|
  };
  /// The records in the common frame and what each gives the segments (use); counts the
  /// degenerate object faces in m.
  FaceNormals make_records(ContactModel& m);
  /// The vector area of the intersection curve (object frame) and what it is made of.
  struct CurveArea {
    Vec3 area{Vec3::Zero()};      ///< Σa: the front part's with history, else all of it
    double abs_sum = 0;           ///< Σ|a| over the same rows
    bool any_front_face = false;  ///< a usable pair's object face faces the previous FD
  };
  /// The vector area from the pairs' segments (contact_segments.hpp), measured from curve_point().
  CurveArea vector_area();
  /// The sums of the last vector_area() (common frame), for the pressure point once FD is known.
  SegmentAreaSum curve_sums{Vec3::Zero()};
  /// ContactModel::pressure_point for FD n (object frame) and the contact plane through `plane`
  /// (object file coordinates): the centre of the area the curve of the last vector_area()
  /// encloses seen along n (else its length-weighted centroid), moved along n onto the plane;
  /// `plane` itself without a curve.
  PodVec3 pressure_point(const Mesh& object, const Vec3& n, const PodVec3& plane) const;
  /// FD into n (unit) from the curve, else the fallbacks; false: no contact direction.
  bool force_direction(ContactModel& m, const CurveArea& curve, const FaceNormals& faces, Vec3& n);
  /// PD along n, both ways (DepthSearch), the probe point (tracked_local, probe-local) and the
  /// contact plane; a concave contact replaces n and PD by the way out of every wall
  /// (clear_planes). `face`: the object face the deepest probe point leaves through (UINT32_MAX:
  /// none). False when there is nothing to render (m then says so, and the history is reset).
  bool penetration(const Mesh& probe, const Mesh& object, Vec3& n, ContactModel& m, Vec3& tracked_local,
                   std::uint32_t& face);
  /// The history the next round starts from: FD n and the held contact (probe point
  /// tracked_local, probe-local, against the face `face` leaves through, or UINT32_MAX).
  void keep_contact(const Vec3& n, const Vec3& tracked_local, std::uint32_t face);

  /// The areas' origin, a point of this round's intersection curve in the common frame: the
  /// midpoint of the first segment of the pairs whose areas are summed (zero: none). Measured
  /// from a point on the patch, Σ|a| compares with |Σa| whatever the faces' size (FD's
  /// cancellation test); from a far vertex of a large face, Σ|a| is inflated and FD falls back.
  Vec3 curve_point() const;
  /// The probe's deepest point under the plane x·normal = offset (object-local): the largest
  /// offset − normal·x over its vertices, by a steepest ascent from the colliding probe faces'
  /// vertices; `vertex` is where (UINT32_MAX: none).
  double probe_support(const Mesh& probe, const Vec3& normal, double offset, std::uint32_t& vertex);
  /// A concave contact: when this round's direction-giving object faces form 2-4 planar clusters
  /// that face each other, n and pd become the smallest translation clearing the probe from every
  /// cluster's plane (contact_planes.hpp), with the probe point and plane point for it; false
  /// (nothing written) otherwise.
  bool clear_planes(const Mesh& probe, Vec3& n, double& pd, Vec3& tracked_local, Vec3& plane_pt);
  PlaneClusters planes;  ///< scratch (clear_planes)

  ContactConfig config;  ///< the builder's knobs
  ///@{
  PatchBody probe_s, object_s;  ///< per-mesh data (prepare()) and per-round state
  ///@}
  // History.
  bool have_prev = false;                ///< prev_n is the last model's FD
  Vec3 prev_n{Vec3::Zero()};             ///< the last model's FD
  bool held_valid = false;               ///< a contact plane to hold
  Vec3 held_n{Vec3::Zero()};             ///< its normal
  Vec3 held_tracked{Vec3::Zero()};       ///< the probe point held against it, probe-local, mm
  std::uint32_t held_face = UINT32_MAX;  ///< the entered surface's face over the tracked point, last found
  /// How far past the entered surface's edge a contact is held: hold_margin_mm, at most
  /// kHoldMarginOfProbe of the probe's bounding radius (prepare(): a probe of 0.005 mm held 1 mm
  /// past a plate's edge would feel a wall 200 of its radii long that is not there).
  double hold_margin = 0;
  /// The held contact, when the model gives no direction (the probe is past a feature it entered,
  /// or touches only its far side): while the tracked point is under the entered surface (a walk
  /// over its faces that face held_n, or within hold_margin past its edge, the last face's
  /// plane extended), fills m with FD = held_n and PD = the depth under it; false: clear of it.
  bool hold(const Mesh& probe, const Mesh& object, ContactModel& m);
  // Scratch.
  std::vector<ContactPair> canonical;                     ///< the pairs sorted and distinct, when not given so
  std::vector<ContactPair> valid;                         ///< the pairs with indices in range
  std::vector<std::array<std::uint32_t, 2>> valid_slots;  ///< per valid pair: its object and probe record slots
  std::vector<Vec3> probe_world;                          ///< probe vertices, object-local (valid where stamped)
  std::vector<std::uint32_t> probe_xform_stamp;           ///< round in which probe_world[v] was computed
  std::uint32_t climb_serial = 0;                         ///< climbs so far (path stamps)
  Eigen::Matrix3d rot{Eigen::Matrix3d::Identity()};       ///< this round's pose rotation
  Vec3 shift{Vec3::Zero()};                               ///< and translation, probe-local → object-local
  bool probe_frame = false;  ///< this round's common frame is the probe's local frame (else the object's)
  /// The common frame's record of a colliding face of body b.
  const FaceRec& common_rec(const PatchBody& b, std::uint32_t slot) const {
    return (&b == &probe_s) == probe_frame ? b.fixed(slot).rec : b.recs[slot];
  }
  /// A point of the object's local frame in the common frame.
  Vec3 to_common(const Vec3& x) const { return probe_frame ? Vec3(rot.transpose() * (x - shift)) : x; }
  /// A direction of the object's local frame in the common frame.
  Vec3 dir_to_common(const Vec3& d) const { return probe_frame ? Vec3(rot.transpose() * d) : d; }
  const Vec3& probe_point(std::uint32_t v, const Mesh& probe);  ///< probe vertex v, object-local
  std::uint32_t epoch = 0;                                      ///< this round's stamp (0: none yet)
  std::vector<std::uint32_t> climb;                             ///< scratch: vertices to climb from
  std::vector<std::uint32_t> seed_pairs;  ///< scratch: valid pairs a search for new regions starts from
};

}  // namespace st::geom
