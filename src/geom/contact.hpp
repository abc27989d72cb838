// Contact model (paper §3.6): from the colliding (probe face, object face) pairs of one
// collision round, the force direction FD, the penetration PD and a local contact plane that
// the haptic thread renders and interpolates from. The result is plain data (ContactModel) so a
// TripleBuffer can carry it; the builder keeps the paper's one piece of history, the first
// contact face. All vectors are in the object's frame (the haptic side's world frame).
//
// Definitions (the paper leaves these open; these are ours):
//  * Nearest pair: over the distinct vertices of the colliding probe faces and the centroids of
//    the colliding, non-degenerate object faces, the pair at the smallest distance (ties: lower
//    object face index, then lower probe vertex index). FD = that object face's outward unit
//    normal (b-a)×(c-a). contact_point = that probe vertex projected onto that face's plane.
//  * First contact face: the nearest object face of the first model with a contact after a model
//    without one (or after reset()); its plane (centroid, normal) is recorded in object-local
//    coordinates. It is re-recorded (flag kReplaned) when contact restarts, and also when its
//    normal and FD differ by more than ContactConfig::replane_angle_deg: measuring PD along a
//    normal that no longer agrees with the force direction makes sliding over a curved surface
//    generate growing force, which the paper's method would do.
//  * PD = max over the colliding probe faces' vertices of their depth below the recorded plane,
//    (p0 - v)·n0, clamped to >= 0. probe_point is that deepest vertex in probe file coordinates.
//  * Local contact plane: normal FD, through probe_point's object-frame position moved by PD
//    along FD, so a probe point's depth below it at the model's pose equals PD. The plane
//    interpolator recomputes depth = (plane_point - pose·probe_point)·FD every tick.
//  * Zero usable pairs (none given, all indices out of range, non-finite pose, or every object
//    face degenerate): no kInContact flag, FD = 0, PD = 0; the first contact face is forgotten.
//  * Normals that disagree: if any colliding object face's normal has a negative dot product
//    with FD (wedged in a crease, a thin wall touched from both sides), kNormalsDisagree is set;
//    FD still follows the nearest face, as in the paper.
//  * Degenerate faces: an object face whose |(b-a)×(c-a)| <= kDegenerateRel · (longest edge)²
//    has no normal; it counts as a contact but is left out of the nearest-face search
//    (kDegenerateSkipped). Degenerate probe faces still contribute their vertices.
#pragma once
#include <cstdint>
#include <span>
#include <type_traits>
#include <vector>

#include "geom/collide.hpp"
#include "geom/mesh.hpp"
#include "geom/pod.hpp"

namespace st::geom {

/// Face with |cross| <= kDegenerateRel · longest edge² is degenerate (sin of its smallest angle
/// below ~1e-12: no direction can be trusted from it).
inline constexpr double kDegenerateRel = 1e-12;

/// ContactModel::flags bits.
enum ContactFlag : std::uint32_t {
  kInContact = 1u << 0,          ///< at least one usable pair: FD, PD and the plane are set
  kNormalsDisagree = 1u << 1,    ///< a colliding object face's normal points against FD
  kReplaned = 1u << 2,           ///< the first-contact plane was (re)recorded by this model
  kDegenerateSkipped = 1u << 3,  ///< degenerate object faces were left out of the FD search
  kBadInput = 1u << 4,           ///< non-finite pose or out-of-range pair indices (skipped)
};

/// One colliding face pair from the collision detection (collide()'s FacePair), faces named by
/// file index, so CollideResult::pairs feeds build() directly.
using ContactPair = FacePair;

/// Everything the haptic side needs from one collision round. Plain data, fixed size.
struct ContactModel {
  std::uint64_t seq = 0;              ///< 1, 2, 3... per builder; 0 = no model yet
  std::uint64_t pose_seq = 0;         ///< sequence number of the pose it was computed at
  std::int64_t pose_sampled_ns = 0;   ///< when that pose was sampled, CLOCK_MONOTONIC ns
  std::int64_t published_ns = 0;      ///< when this model was published, CLOCK_MONOTONIC ns
  PodPose pose;                       ///< probe→object pose it was computed at
  PodVec3 force_dir;                  ///< FD, unit outward normal of the nearest object face; 0 if none
  PodVec3 contact_point;              ///< nearest probe vertex projected on the nearest face, mm
  PodVec3 probe_point;                ///< deepest probe vertex, probe file coordinates, mm
  PodVec3 plane_point;                ///< local contact plane: a point, mm (normal = force_dir)
  double penetration_mm = 0;          ///< PD >= 0 against the first contact face
  std::uint32_t object_faces = 0;     ///< distinct colliding object faces
  std::uint32_t probe_faces = 0;      ///< distinct colliding probe faces
  std::uint32_t contacts = 0;         ///< object_faces + probe_faces (paper §3.5)
  std::uint32_t pairs = 0;            ///< face pairs given (including skipped ones)
  std::uint32_t nearest_object_face = UINT32_MAX;  ///< the face FD comes from
  std::uint32_t nearest_probe_vertex = UINT32_MAX; ///< the probe vertex of the nearest pair
  std::uint32_t first_contact_face = UINT32_MAX;   ///< the recorded face PD is measured against
  std::uint32_t deepest_probe_vertex = UINT32_MAX; ///< the vertex probe_point comes from
  std::uint32_t skipped_pairs = 0;    ///< pairs with an index out of range
  std::uint32_t degenerate_faces = 0; ///< distinct degenerate colliding object faces
  std::uint32_t flags = 0;            ///< ContactFlag bits
  std::uint32_t reserved = 0;         ///< padding, zero

  bool in_contact() const { return (flags & kInContact) != 0; }  ///< FD/PD/plane are meaningful
};
static_assert(std::is_trivially_copyable_v<ContactModel>);
static_assert(sizeof(ContactModel) == 280, "ContactModel layout is pinned (shared memory, telemetry)");

/// Builder knobs; DefaultContactConfig() gives the documented defaults.
struct ContactConfig {
  double replane_angle_deg = 60.0;  ///< re-record the first contact face when FD turns further than this
};
/// The defaults: re-record the first-contact plane past 60°.
ContactConfig DefaultContactConfig();

/// Builds ContactModels from face pairs, remembering the first contact face between calls.
/// Not thread-safe; owned by the collision thread. Reuses its scratch memory between calls.
class ContactBuilder {
 public:
  explicit ContactBuilder(ContactConfig config = DefaultContactConfig());
  /// The model for `pairs` found at `pose` (probe file → object file coordinates). Fills every
  /// field but seq/pose_seq/pose_sampled_ns/published_ns, which belong to the publisher.
  ContactModel build(const Mesh& probe, const Mesh& object, const Pose& pose,
                     std::span<const ContactPair> pairs);
  /// Forgets the first contact face (as if contact had ended).
  void reset();
  /// True while a first contact face is recorded.
  bool has_first_face() const { return first_face_ != UINT32_MAX; }

 private:
  ContactConfig config_;
  std::uint32_t first_face_ = UINT32_MAX;  ///< recorded face, UINT32_MAX = none
  Vec3 first_point_{Vec3::Zero()};         ///< its centroid, object-local, mm
  Vec3 first_normal_{Vec3::Zero()};        ///< its unit normal
  std::vector<std::uint32_t> probe_faces_, object_faces_, probe_vertices_;  ///< scratch
  std::vector<Vec3> probe_points_;         ///< scratch: probe vertices in object-local coordinates
};

}  // namespace st::geom
