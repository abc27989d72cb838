// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// Contact models: from the colliding (probe face, object face) pairs of one collision round, the
/// force direction FD, the penetration PD and a local contact plane that the haptic thread renders
/// and interpolates from. The result is plain data (ContactModel) so a TripleBuffer can carry it.
/// Frames (named as in mesh.hpp): `pose` maps the probe frame into the object frame, the frame
/// the builder works in (the haptic side's world). Every vector of ContactModel is in the object
/// frame except probe_point, which is a probe vertex in the probe frame (the haptic side moves it
/// with the pose of each tick).
//
// Two models, chosen by ContactConfig::model:
//
// "patch" (the default; contact_patch.cpp). What a haptics engineer ships: depth and direction
// continuous in the pose, no pop-through, edges and wedges blended.
//  * FD = the vector area of the object surface inside the probe, A = ∫ n dA, normalised. It is
//    computed from the intersection curve alone (Stokes: A = ½ ∮ x × dx over the curve, each
//    colliding pair contributing its triangle–triangle intersection segment oriented along
//    n_object × n_probe). A is minus the gradient of the intersection volume with respect to the
//    probe's translation, so force along A is the direction of a conservative (volume) penalty;
//    it turns continuously as the probe slides over an edge (the two faces' shares of the patch
//    change continuously) and sits on the bisector in a wedge.
//  * History, for thin features: while contact continues, object faces turned away from the
//    previous FD (n·FD_prev < kBackCos) do not count in A, and the depth is measured through the
//    faces that face FD. A probe pushed into a thin plate keeps being pushed out of the side it
//    entered, however deep it goes.
//  * PD = the directional penetration depth along FD: how far the probe must move along FD to
//    come out. Measured at probe vertices inside the object (the distance along FD to the
//    object's faces that face FD, found by walking across them from a colliding face), at object
//    vertices inside the probe (along -FD to the probe's faces), and where the deepest vertex's
//    edges cross the other body's edges seen along FD (the ridge of a box edge pressed into a
//    finely meshed probe lies between vertices; the search follows a ridge from fan to fan).
//    The deepest vertex is found by a climb over the mesh graph from the colliding faces'
//    vertices (the distance grows toward the deepest point), so vertices wholly inside count
//    and the cost is the length of the climb, not the number of vertices inside; last round's
//    local maxima start the next round, and new contact regions are searched every few rounds.
//    Exact for a face, and for a symmetric press on an edge or corner of a box or on a sphere (up
//    to the meshes' vertex spacing); continuous in the pose. Where the patch is not symmetric (a
//    ball half over an edge) FD is the volume gradient, not the shortest way out, and PD is the
//    way out along FD: the force stays conservative and continuous rather than turning to the
//    nearest feature.
//  * Held contact (a surface-constrained proxy): when the probe has passed through a thin
//    feature, so that no front face collides any more, FD is kept while the tracked probe point
//    (the deepest one when contact was last rendered) is under the surface it entered: a walk
//    over that surface's faces that face FD, from the face found last round, finds the face over
//    the point (or, within hold_margin_mm, at most a quarter of the probe's bounding radius, past
//    the surface's edge, the last face's plane extended); PD is the depth under it (flag kHeld). It ends once the point is clear on the
//    entry side. The proxy shown to a user is the probe moved out by PD along FD
//    (ContactModel::proxy_offset()).
//  * Open surfaces (a sheet, a scan open at its base: a part with no inside, orient.hpp) have no
//    side of their own: a contact takes the side the probe is on. At a first contact that meets
//    an open part's faces the model is built both ways, as the faces are wound and with the open
//    parts' faces wound the other way, and the one with the smaller PD is kept (the probe is
//    less deep on the side it came from) for as long as the contact lasts; the next contact
//    chooses again. For an object with open parts the builder keeps a second copy of the mesh (its
//    vertices and faces) and of the model's per-mesh state.
//  * Corners at one position are one vertex (coincident_vertices()): a mesh written as a soup,
//    or split at its seams, renders as the welded mesh, bit for bit. A face written again on the
//    same corners (a double-sided sheet, fin or shell: each face also the other way round; a face
//    an exporter repeated) is one face, the first (pairs with the others count as pairs with it),
//    and a surface so joined is wound consistently; the wall two solids share (written both ways,
//    its rim all on other faces: voxels, parts glued face to face) stays as written, its sides
//    cancelling as the union's surface has no wall there. The builder keeps a joined copy of
//    such a mesh (each position once, the faces in their order, the repeats left as points).
//  * Order: the model is a function of the set of pairs. They are taken in (probe, object)
//    order, each once (sorted in scratch when not given so), and the segments' areas are
//    measured from a point of the intersection curve, so neither the worker count nor the
//    faces' size changes FD, PD or the force.
//  * Fallbacks: when the pairs give no usable curve (touching or coplanar faces only), FD = the
//    area-weighted mean normal of the colliding object faces (flag kNormalFallback); when that is
//    zero too, the previous FD; a patch whose faces cancel (|A| < kCancelRatio · Σ|a|) keeps the
//    previous FD and sets kNormalsDisagree.
//
// "paper" (paper §3.6, kept exactly for the Table 2 reproduction; contact.cpp):
//  * Nearest pair: over the distinct vertices of the colliding probe faces and the centroids of
//    the colliding, non-degenerate object faces, the pair at the smallest distance (ties: lower
//    object face index, then lower probe vertex index). FD = that object face's outward unit
//    normal (b-a)×(c-a). contact_point = that probe vertex projected onto that face's plane.
//  * First contact face: the nearest object face of the first model with a contact after a model
//    without one (or after reset()); its plane (centroid, normal) is recorded in the object's local
//    coordinates. It is re-recorded (flag kReplaned) when contact restarts, and also when its
//    normal and FD differ by more than ContactConfig::replane_angle_deg.
//  * PD = max over the colliding probe faces' vertices of their depth below the recorded plane,
//    (p0 - v)·n0, clamped to >= 0. probe_point is that deepest vertex.
//  * Normals that disagree: if any colliding object face's normal has a negative dot product
//    with FD (wedged in a crease, a thin wall touched from both sides), kNormalsDisagree is set;
//    FD still follows the nearest face, as in the paper.
//
// Both models:
//  * Local contact plane: normal FD, through probe_point's object-frame position moved by PD
//    along FD, so a probe point's depth below it at the model's pose equals PD. The plane
//    interpolator recomputes depth = (plane_point - pose·probe_point)·FD every tick.
//  * Zero usable pairs (none given, all indices out of range, non-finite pose, or every object
//    face degenerate) and no held contact: no kInContact flag, FD = 0, PD = 0; history is reset.
//  * Degenerate faces: an object face whose |(b-a)×(c-a)| <= kDegenerateRel · (longest edge)²
//    has no normal: it counts as a contact but gives no direction (kDegenerateSkipped).
#pragma once
#include <spheretouch/abi.hpp>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include <spheretouch/geom/collide.hpp>
#include <spheretouch/geom/mesh.hpp>
#include <spheretouch/geom/pod.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

/// Face with |cross| <= kDegenerateRel · longest edge² is degenerate (sin of its smallest angle
/// below ~1e-12: no direction can be trusted from it).
inline constexpr double kDegenerateRel = 1e-12;

/// Patch model: an object face is "front" (faces the contact direction) when n·FD > kFrontCos.
/// cos 85°: a face tilted up to 85° from FD still bounds the depth; steeper walls and back faces
/// (the far side of a thin plate) do not.
inline constexpr double kFrontCos = 0.0872;
/// Patch model: while contact continues, an object face turned more than 120° from the previous FD
/// (n·FD < kBackCos) is the far side of what the probe entered (a thin plate's underside, the
/// opposite wall of a slot) and gives no direction; the sides of a convex or concave 90° edge do.
inline constexpr double kBackCos = -0.5;
/// Patch model: |A| below this fraction of Σ|a| over the pairs (the pieces of the curve) means the
/// patch's normals cancel (a probe through a thin wall, pinched from two sides): FD is not
/// trusted from it.
inline constexpr double kCancelRatio = 0.05;

/// ContactModel::flags bits.
enum ContactFlag : std::uint32_t {
  kInContact = 1u << 0,          ///< at least one usable pair: FD, PD and the plane are set
  kNormalsDisagree = 1u << 1,    ///< paper: a colliding face points against FD; patch: the patch's normals cancel
  kReplaned = 1u << 2,           ///< paper: the first-contact plane was (re)recorded by this model
  kDegenerateSkipped = 1u << 3,  ///< degenerate object faces gave no direction
  kBadInput = 1u << 4,           ///< non-finite pose or out-of-range pair indices (skipped)
  kHeld = 1u << 5,               ///< patch: held contact, the probe is past a feature it entered (proxy)
  kNormalFallback = 1u << 6,     ///< patch: FD from face normals or history, not from the intersection curve
  kInsideCapped = 1u << 7,       ///< patch: the depth search hit ContactConfig::max_inside_vertices
  kPlanes = 1u << 8,             ///< patch: FD and PD clear several planes at once (a concave contact)
};

/// Which contact model a builder computes.
enum class ContactModelKind : std::uint32_t { paper = 0, patch = 1 };
/// "paper" | "patch".
Result<ContactModelKind> parse_contact_model(std::string_view name);
/// The name parse_contact_model() accepts.
const char* to_string(ContactModelKind kind);

/// One colliding face pair from the collision detection (collide()'s FacePair), faces named by
/// file index, so CollideResult::pairs feeds build() directly.
using ContactPair = FacePair;

/// Everything the haptic side needs from one collision round. Plain data, fixed size.
struct ContactModel {
  std::uint64_t seq = 0;             ///< 1, 2, 3... per builder; 0 = no model yet
  std::uint64_t pose_seq = 0;        ///< sequence number of the pose it was computed at
  std::int64_t pose_sampled_ns = 0;  ///< when that pose was sampled, CLOCK_MONOTONIC ns
  std::int64_t published_ns = 0;     ///< when this model was published, CLOCK_MONOTONIC ns
  PodPose pose;                      ///< probe→object pose it was computed at
  PodVec3 force_dir;                 ///< FD, unit, pushes the probe out of the object; 0 if none
  PodVec3 contact_point;  ///< paper: nearest probe vertex on the nearest face; patch: where the deepest point leaves the surface, mm
  PodVec3 probe_point;  ///< deepest probe point, probe frame, mm
  PodVec3 plane_point;  ///< local contact plane: a point, mm (normal = force_dir)
  /// Where the force acts, for its moment (the wrench's torque), object file coordinates, mm.
  /// patch: the centroid of the area the intersection curve encloses seen along FD (a uniform
  /// pressure's centre: the middle of a flat press, the foot of a sphere's centre; without area
  /// along FD the curve's length-weighted centroid), on the contact plane (plane_point, FD);
  /// held contact and paper: contact_point.
  PodVec3 pressure_point;
  double penetration_mm = 0;       ///< PD >= 0 (paper: below the first contact face; patch: directional depth)
  std::uint32_t object_faces = 0;  ///< distinct colliding object faces
  std::uint32_t probe_faces = 0;   ///< distinct colliding probe faces
  std::uint32_t contacts = 0;      ///< object_faces + probe_faces (paper §3.5)
  std::uint32_t pairs = 0;         ///< face pairs given (including skipped ones)
  /// paper: the face FD comes from; patch: the face the deepest point leaves through
  std::uint32_t nearest_object_face = UINT32_MAX;
  std::uint32_t nearest_probe_vertex = UINT32_MAX;  ///< paper: the probe vertex of the nearest pair
  std::uint32_t first_contact_face = UINT32_MAX;    ///< paper: the recorded face PD is measured against
  /// the probe vertex probe_point comes from (UINT32_MAX: an object vertex was deepest)
  std::uint32_t deepest_probe_vertex = UINT32_MAX;
  std::uint32_t skipped_pairs = 0;           ///< pairs with an index out of range
  std::uint32_t degenerate_faces = 0;        ///< distinct degenerate colliding object faces
  std::uint32_t flags = 0;                   ///< ContactFlag bits
  std::uint32_t kind = 0;                    ///< ContactModelKind that built it
  std::uint32_t inside_probe_vertices = 0;   ///< patch: probe vertices the depth search found inside the object
  std::uint32_t inside_object_vertices = 0;  ///< patch: object vertices the depth search found inside the probe

  bool in_contact() const { return (flags & kInContact) != 0; }  ///< FD/PD/plane are meaningful
  /// Where the probe is shown (the proxy): the probe moved out of the object by PD along FD, mm.
  Vec3 proxy_offset() const { return penetration_mm * to_eigen(force_dir); }
};
static_assert(std::is_trivially_copyable_v<ContactModel>);
static_assert(sizeof(ContactModel) == 312, "ContactModel layout is pinned (shared memory, telemetry)");

/// Objects a ContactSet carries at most: the probe touching (or just leaving) more objects than
/// this at once renders the kMaxContactObjects deepest, and the set counts the rest (overflow).
inline constexpr std::uint32_t kMaxContactObjects = 8;

/// The contact models of one collision round over a scene of one or more objects, for the
/// haptic side: one model per object the probe touches, and a "no contact" model for an object it
/// left this round (it ends that object's contact). Every vector of the models is in the world
/// frame (the objects' placements applied), `pose` maps the probe into the world, so the servo
/// needs no placement. A single-object scene sends its one model every round. Plain data, fixed
/// size (a TripleBuffer in shared memory carries it).
struct ContactSet {
  std::uint64_t seq = 0;             ///< 1, 2, 3... per collision loop; 0 = none yet
  std::uint64_t pose_seq = 0;        ///< the pose the round answered
  std::int64_t pose_sampled_ns = 0;  ///< when that pose was sampled, CLOCK_MONOTONIC ns
  std::int64_t published_ns = 0;     ///< when the set was published, CLOCK_MONOTONIC ns
  std::uint32_t count = 0;           ///< models in use (<= kMaxContactObjects)
  std::uint32_t overflow = 0;        ///< objects in contact this round left out (beyond kMaxContactObjects)
  std::uint32_t contacts = 0;        ///< paper §3.5 contacts summed over the models
  std::uint32_t reserved = 0;        ///< zero
  std::uint32_t object[kMaxContactObjects] = {};  ///< scene object index of models[i]
  ContactModel models[kMaxContactObjects];        ///< models[0 .. count)
  /// A set of one model for object 0 (a single-object scene), with the model's sequence numbers and times.
  static ContactSet of(const ContactModel& m) {
    ContactSet s;
    s.seq = m.seq;
    s.pose_seq = m.pose_seq;
    s.pose_sampled_ns = m.pose_sampled_ns;
    s.published_ns = m.published_ns;
    s.count = 1;
    s.contacts = m.contacts;
    s.models[0] = m;
    return s;
  }
};
static_assert(std::is_trivially_copyable_v<ContactSet>);

/// `m` (built in an object's own frame) moved into the world by the object's placement
/// (object frame → world): the pose, FD and every point but probe_point (a probe-frame point).
ContactModel place(const ContactModel& m, const Pose& placement);

/// Builder knobs; DefaultContactConfig() gives the documented defaults.
struct ContactConfig {
  ContactModelKind model = ContactModelKind::patch;  ///< which model
  double replane_angle_deg = 60.0;  ///< paper: re-record the first contact face when FD turns further than this
  /// patch: a held contact lasts this far past the edge of the surface it entered (at most a
  /// quarter of the probe's bounding radius: a tiny probe is not held far past a tiny plate)
  double hold_margin_mm = 1.0;
  /// patch: vertices the depth search may visit per body and round (kInsideCapped past it)
  std::uint32_t max_inside_vertices = 1u << 18;
};
/// patch model, paper replane angle 60°, hold margin 1 mm, 262,144 inside vertices per side.
ContactConfig DefaultContactConfig();
/// Empty when the config is usable, else a message naming the bad field.
std::string check(const ContactConfig& config);

/// The faces around each vertex of a mesh (compressed rows): the faces of vertex v are
/// faces[first[v]] .. faces[first[v + 1] - 1]. Built once per mesh for the patch model's climbs
/// and surface walks (neighbouring vertices and faces are found through it); 4 bytes per vertex plus 12 per
/// face (about 28 bytes per vertex on a closed mesh).
struct VertexFaces {
  std::vector<std::uint32_t> first;  ///< row starts, num_vertices + 1
  std::vector<std::uint32_t> faces;  ///< incident face indices
  /// Builds it from the faces (indices out of range are skipped).
  static VertexFaces build(const Mesh& mesh);
  std::size_t bytes() const { return (first.size() + faces.size()) * sizeof(std::uint32_t); }  ///< memory held
};

struct SurfaceWalk;  // surface_walk.hpp
class DepthSearch;   // contact_depth.hpp

/// Builds ContactModels from face pairs, remembering the model's history between calls (paper:
/// the first contact face; patch: the previous FD and the held plane). Not thread-safe; owned by
/// the collision thread. Reuses its scratch memory between calls.
class ContactBuilder {
 public:
  explicit ContactBuilder(ContactConfig config = DefaultContactConfig());  ///< config must pass check()
  ~ContactBuilder();
  ContactBuilder(ContactBuilder&&) noexcept;             ///< takes the history and scratch
  ContactBuilder& operator=(ContactBuilder&&) noexcept;  ///< takes the history and scratch
  /// Builds what the model needs per mesh (the patch model's VertexFaces, ~28 B/vertex) so
  /// that the first build() does not pay for it; build() calls it when the meshes changed.
  void prepare(const Mesh& probe, const Mesh& object);
  /// The model for `pairs` found at `pose` (probe frame → object frame). Fills every
  /// field but seq/pose_seq/pose_sampled_ns/published_ns, which belong to the publisher.
  ContactModel build(const Mesh& probe, const Mesh& object, const Pose& pose, std::span<const ContactPair> pairs);
  /// Forgets the history (as if contact had ended).
  void reset();
  /// paper: true while a first contact face is recorded; patch: true while a previous FD is kept.
  bool has_first_face() const;
  const ContactConfig& config() const { return config_; }  ///< its knobs
  std::size_t bytes() const;                               ///< memory held for the meshes (adjacency) and scratch

 private:
  ContactModel build_paper(const Mesh& probe, const Mesh& object, const Pose& pose, std::span<const ContactPair> pairs);
  ContactModel build_patch(const Mesh& probe, const Mesh& object, const Pose& pose, std::span<const ContactPair> pairs);
  ContactModel build_patch_joined(const Mesh& probe, const Mesh& object, const Pose& pose,
                                  std::span<const ContactPair> pairs);
  ContactConfig config_;
  std::uint32_t first_face_ = UINT32_MAX;  ///< paper: recorded face, UINT32_MAX = none
  Vec3 first_point_{Vec3::Zero()};         ///< paper: its centroid, object local frame, mm
  Vec3 first_normal_{Vec3::Zero()};        ///< paper: its unit normal
  std::vector<std::uint32_t> probe_faces_, object_faces_, probe_vertices_;  ///< scratch
  std::vector<Vec3> probe_points_;  ///< scratch: probe vertices in the object's local frame
  struct Patch;                     ///< the patch model's state and scratch (contact_patch.hpp)
  friend struct SurfaceWalk;        // the patch model's parts that name Patch
  friend class DepthSearch;
  friend struct PatchTestAccess;  // tests/geom: the patch model's parts, tested one at a time
  std::unique_ptr<Patch> patch_;
  /// patch: the object with its open parts wound the other way, and a model of its own for a
  /// contact on their back (contact.cpp).
  struct Back;
  std::unique_ptr<Back> back_;
  Back& back_for(const Mesh& object);
  /// patch: a mesh whose corners repeat (coincident_vertices(): a soup, seams) as the model reads
  /// it, each position once and the faces in their order (contact.cpp).
  struct Joined;
  std::unique_ptr<Joined> joined_[2];     // probe, object
  std::vector<ContactPair> named_pairs_;  // scratch: the pairs with repeated faces named by their first
  const Mesh& joined(const Mesh& mesh, int which);
};

}  // namespace st::geom
