// SPDX-License-Identifier: BSD-3-Clause
// Contact models from colliding face pairs: the builder, the configuration and the paper's model
// (§3.6); the patch model is in contact_patch.cpp. Definitions in contact.hpp.
#include <spheretouch/geom/contact.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <spheretouch/geom/check.hpp>
#include <spheretouch/geom/contact_patch.hpp>
#include <spheretouch/geom/orient.hpp>

namespace st::inline SPHERETOUCH_ABI::geom {

Result<ContactModelKind> parse_contact_model(std::string_view name) {
  if (name == "paper") return ContactModelKind::paper;
  if (name == "patch") return ContactModelKind::patch;
  return fail("contact model '", std::string(name), "': expected patch or paper");
}

const char* to_string(ContactModelKind kind) {
  switch (kind) {
    case ContactModelKind::paper:
      return "paper";
    case ContactModelKind::patch:
      return "patch";
  }
  return "?";
}

ContactModel place(const ContactModel& m, const Pose& placement) {
  ContactModel w = m;
  const Eigen::Matrix3d R = placement.linear();
  w.pose = to_pod(Pose(placement * to_eigen(m.pose)));
  w.force_dir = to_pod(Vec3(R * to_eigen(m.force_dir)));
  for (PodVec3 ContactModel::*p : {&ContactModel::contact_point, &ContactModel::plane_point, &ContactModel::pressure_point})
    w.*p = to_pod(Vec3(placement * to_eigen(m.*p)));
  return w;
}

ContactConfig DefaultContactConfig() { return ContactConfig{}; }

std::string check(const ContactConfig& c) {
  std::ostringstream os;
  if (c.model != ContactModelKind::paper && c.model != ContactModelKind::patch)
    os << "contact: model = " << static_cast<unsigned>(c.model) << ", expected patch or paper";
  else if (!(std::isfinite(c.replane_angle_deg) && c.replane_angle_deg >= 0 && c.replane_angle_deg <= 180))
    os << "contact: replane_angle_deg = " << c.replane_angle_deg << ", expected a value in [0, 180]";
  else if (!(std::isfinite(c.hold_margin_mm) && c.hold_margin_mm >= 0))
    os << "contact: hold_margin_mm = " << c.hold_margin_mm << ", expected a finite value >= 0";
  else if (c.max_inside_vertices < 1)
    os << "contact: max_inside_vertices = 0, expected >= 1";
  return os.str();
}

ContactBuilder::ContactBuilder(ContactConfig config) : config_(config), patch_(std::make_unique<Patch>(config)) {
  ST_ASSERT(check(config).empty(), "a ContactBuilder's config passes check() (contact.hpp)");
}
namespace {

// Which mesh something was made from: its address and sizes (as PatchBody::sized_for).
struct MadeFor {
  const Mesh* of = nullptr;
  std::size_t nv = 0, nf = 0;
  MadeFor() = default;
  explicit MadeFor(const Mesh& m) : of(&m), nv(m.local.size()), nf(m.faces.size()) {}
  bool operator()(const Mesh& m) const { return of == &m && nv == m.local.size() && nf == m.faces.size(); }
};

// Whether every face's corners name vertices of the mesh (the model skips a face that does not;
// the part analysis and the joined copy need them all).
bool corners_in_range(const Mesh& m) {
  const std::size_t nv = m.local.size();
  return std::all_of(m.faces.begin(), m.faces.end(), [nv](const Tri& t) { return t[0] < nv && t[1] < nv && t[2] < nv; });
}

// Whether face t (distinct corners) runs its corners in ascending order, up to rotation.
bool ascending(const Tri& t) {
  const int m = t[0] < t[1] ? (t[0] < t[2] ? 0 : 2) : (t[1] < t[2] ? 1 : 2);
  return t[(m + 1) % 3] < t[(m + 2) % 3];
}

// Faces written again on the same three corners, each named by the first of them (the result,
// per face; empty when none is), the others made a point in `faces` so no walk crosses them.
// Twice the other way round is either the two sides of one sheet (double-sided geometry) or the
// wall two solids share (voxels, an assembly's parts glued face to face): a wall's two faces
// cancel in the patch's vector area, as the surface of the solids' union should, so they stay.
// Which is which: the repeats, joined across the edges they share, make regions; a region whose
// rim is all attached to other faces and whose faces are all written both ways is a wall; any
// other (a free rim, a fin's rim partly free, no rim: a closed surface written twice) is one
// face. A face repeated the same way is one face.
std::vector<std::uint32_t> first_of_repeats(std::vector<Tri>& faces) {
  constexpr std::uint32_t kNone = UINT32_MAX;
  const auto nf = static_cast<std::uint32_t>(faces.size());
  std::vector<std::pair<Tri, std::uint32_t>> keyed;
  keyed.reserve(nf);
  for (std::uint32_t f = 0; f < nf; ++f) {
    Tri k = faces[f];
    std::sort(k.begin(), k.end());
    if (k[0] != k[1] && k[1] != k[2]) keyed.push_back({k, f});  // (a degenerate face is a point or a segment)
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<std::uint32_t> group(nf, kNone), first;  // a repeated face's group; a group's first face
  std::vector<std::uint8_t> both_ways;
  for (std::size_t i = 0; i < keyed.size();) {
    std::size_t e = i + 1;
    while (e < keyed.size() && keyed[e].first == keyed[i].first) ++e;
    if (e - i > 1) {
      const auto g = static_cast<std::uint32_t>(first.size());
      first.push_back(keyed[i].second);  // (ties sort by face id: the lowest)
      both_ways.push_back(0);
      for (std::size_t k = i; k < e; ++k) {
        group[keyed[k].second] = g;
        both_ways[g] |= ascending(faces[keyed[k].second]) != ascending(faces[keyed[i].second]);
      }
    }
    i = e;
  }
  if (first.empty()) return {};
  // The edges' uses, grouped by edge.
  struct Use {
    std::uint64_t key;
    std::uint32_t face;
  };
  std::vector<Use> uses;
  uses.reserve(std::size_t(nf) * 3);
  for (std::uint32_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = std::min(faces[f][k], faces[f][(k + 1) % 3]),
                          b = std::max(faces[f][k], faces[f][(k + 1) % 3]);
      if (a != b) uses.push_back({std::uint64_t(a) << 32 | b, f});
    }
  std::sort(uses.begin(), uses.end(), [](const Use& x, const Use& y) { return x.key < y.key; });
  std::vector<std::uint32_t> root(first.size());
  for (std::uint32_t g = 0; g < root.size(); ++g) root[g] = g;
  auto find = [&](std::uint32_t g) {
    while (root[g] != g) g = root[g] = root[root[g]];
    return g;
  };
  struct Edge {
    std::size_t begin, end;
  };
  std::vector<Edge> shared;  // the edges a repeated face uses
  std::vector<std::uint32_t> groups;
  for (std::size_t i = 0; i < uses.size();) {
    std::size_t e = i;
    std::uint32_t g0 = kNone;
    for (; e < uses.size() && uses[e].key == uses[i].key; ++e)
      if (const std::uint32_t g = group[uses[e].face]; g != kNone) {
        if (g0 == kNone) g0 = g;
        root[find(g)] = find(g0);  // groups meeting at an edge are one region
      }
    if (g0 != kNone) shared.push_back({i, e});
    i = e;
  }
  std::vector<std::uint8_t> rim(first.size(), 0), free_rim(first.size(), 0), one_way(first.size(), 0);
  for (const Edge& ed : shared) {
    groups.clear();
    bool other = false;
    for (std::size_t k = ed.begin; k < ed.end; ++k) {
      const std::uint32_t g = group[uses[k].face];
      if (g == kNone)
        other = true;
      else
        groups.push_back(g);
    }
    std::sort(groups.begin(), groups.end());
    if (std::unique(groups.begin(), groups.end()) - groups.begin() != 1) continue;  // inside a region
    const std::uint32_t r = find(groups[0]);
    rim[r] = 1;  // on the region's rim
    free_rim[r] |= !other;
  }
  for (std::uint32_t g = 0; g < first.size(); ++g) one_way[find(g)] |= !both_ways[g];
  std::vector<std::uint32_t> face_of;
  for (std::uint32_t f = 0; f < nf; ++f) {
    const std::uint32_t g = group[f];
    if (g == kNone || f == first[g]) continue;
    const std::uint32_t r = find(g);
    if (rim[r] && !free_rim[r] && !one_way[r]) continue;  // a wall between solids: both sides stay
    if (face_of.empty()) {
      face_of.resize(nf);
      for (std::uint32_t h = 0; h < nf; ++h) face_of[h] = h;
    }
    face_of[f] = first[g];
    faces[f] = {faces[f][0], faces[f][0], faces[f][0]};
  }
  return face_of;
}

}  // namespace

/// The object as a contact on the back of its open parts sees it (contact.hpp, top): its open
/// parts' faces wound the other way, and a patch model of its own. Made once per object mesh.
struct ContactBuilder::Back {
  MadeFor made_for;                // the object it was made for
  std::vector<std::uint8_t> open;  // per face: in an open part (empty: none)
  Mesh mesh;                       // the object with the open faces flipped
  std::unique_ptr<Patch> patch;
  bool active = false;  // the contact in progress is on the back
};

ContactBuilder::Back& ContactBuilder::back_for(const Mesh& object) {
  if (!back_) back_ = std::make_unique<Back>();
  Back& b = *back_;
  if (b.made_for(object)) return b;
  b = Back{};
  b.made_for = MadeFor(object);
  if (!corners_in_range(object)) return b;  // (no open parts read from faces that name no vertex)
  b.open = open_part_faces(object);
  if (std::find(b.open.begin(), b.open.end(), 1) == b.open.end()) {
    b.open.clear();
    return b;
  }
  b.mesh.name = object.name;
  b.mesh.origin = object.origin;
  b.mesh.local = object.local;
  b.mesh.faces = object.faces;
  for (std::size_t f = 0; f < b.open.size(); ++f)
    if (b.open[f]) std::swap(b.mesh.faces[f][1], b.mesh.faces[f][2]);
  b.patch = std::make_unique<Patch>(config_);
  return b;
}

/// A mesh as the patch model reads it. The model walks the surface from vertex to vertex (the
/// depth climb, the walks under a held contact, the open parts): a surface whose corners are
/// written once per face (a soup) would have no walk past a face, and a face written twice (a
/// double-sided sheet: each face again the other way round; a face repeated by an exporter)
/// would cancel or double the surface it is part of. Here each position is one vertex, a face
/// written again is the first face of its corners (first_of_repeats(): the pairs name that one,
/// `face_of`; the others stay in place as a point, so every face keeps its id; the wall two
/// solids share stays as written), and the faces so made one surface are wound consistently
/// (orient_faces(): which way a face written both ways is wound is not in the file). Made once
/// per mesh, and only for a mesh with repeats.
struct ContactBuilder::Joined {
  MadeFor made_for;      // the mesh it was made for
  bool repeats = false;  // some corners or faces repeat: `mesh` is the joined copy
  Mesh mesh;
  std::vector<std::uint32_t> vertex_of;  // its vertex -> the mesh's (the lowest at that position)
  std::vector<std::uint32_t> face_of;    // the mesh's face -> the first face of its corners (empty: none repeat)
};

const Mesh& ContactBuilder::joined(const Mesh& mesh, int which) {
  if (!joined_[which]) joined_[which] = std::make_unique<Joined>();
  Joined& j = *joined_[which];
  if (!j.made_for(mesh)) {
    const bool was_copy = j.repeats;
    j = Joined{};
    j.made_for = MadeFor(mesh);
    if (!corners_in_range(mesh)) return mesh;  // read as given (the model skips such faces)
    const std::vector<std::uint32_t> same = coincident_vertices(mesh);
    std::vector<std::uint32_t> id(same.size());
    for (std::size_t v = 0; v < same.size(); ++v) {
      id[v] = same[v] == v ? std::uint32_t(j.vertex_of.size()) : id[same[v]];
      if (same[v] == v) j.vertex_of.push_back(std::uint32_t(v));
    }
    std::vector<Tri> faces = mesh.faces;
    for (Tri& t : faces)
      for (std::uint32_t& v : t)
        if (v < id.size()) v = id[v];  // (an index out of range stays so: build() skips its pairs)
    j.face_of = first_of_repeats(faces);
    j.repeats = j.vertex_of.size() < same.size() || !j.face_of.empty();
    if (j.repeats) {
      j.mesh.name = mesh.name;
      j.mesh.origin = mesh.origin;
      j.mesh.local.reserve(j.vertex_of.size());
      for (std::uint32_t v : j.vertex_of) j.mesh.local.push_back(mesh.local[v]);
      j.mesh.faces = std::move(faces);
      if (!j.face_of.empty()) (void)orient_faces(j.mesh);
    } else {
      j.vertex_of = {};  // (its capacity too: a vertex each)
    }
    // What was made for the copy this one replaces (at the same address) is not for it.
    if (was_copy || j.repeats) {
      patch_ = std::make_unique<Patch>(config_);
      back_.reset();
    }
  }
  return j.repeats ? j.mesh : mesh;
}

ContactBuilder::~ContactBuilder() = default;
ContactBuilder::ContactBuilder(ContactBuilder&&) noexcept = default;
ContactBuilder& ContactBuilder::operator=(ContactBuilder&&) noexcept = default;

void ContactBuilder::reset() {
  first_face_ = UINT32_MAX;
  first_point_.setZero();
  first_normal_.setZero();
  patch_->reset();
  if (back_ && back_->patch) back_->patch->reset();
  if (back_) back_->active = false;
}

bool ContactBuilder::has_first_face() const {
  if (config_.model == ContactModelKind::paper) return first_face_ != UINT32_MAX;
  return back_ && back_->active ? back_->patch->has_history() : patch_->has_history();
}

void ContactBuilder::prepare(const Mesh& probe, const Mesh& object) {
  if (config_.model != ContactModelKind::patch) return;
  const Mesh& p = joined(probe, 0);
  const Mesh& o = joined(object, 1);
  patch_->prepare(p, o);
  if (Back& b = back_for(o); b.patch) b.patch->prepare(p, b.mesh);
}

std::size_t ContactBuilder::bytes() const {
  std::size_t back = 0;
  if (back_ && back_->patch)
    back = back_->patch->bytes() + back_->open.capacity() + back_->mesh.local.capacity() * sizeof(Vec3) +
           back_->mesh.faces.capacity() * sizeof(Tri);
  for (const auto& j : joined_)
    if (j && j->repeats)
      back += j->mesh.local.capacity() * sizeof(Vec3) + j->mesh.faces.capacity() * sizeof(Tri) +
              (j->vertex_of.capacity() + j->face_of.capacity()) * 4;
  back += named_pairs_.capacity() * sizeof(ContactPair);
  return patch_->bytes() + back + (probe_faces_.capacity() + object_faces_.capacity() + probe_vertices_.capacity()) * 4 +
         probe_points_.capacity() * sizeof(Vec3);
}

ContactModel ContactBuilder::build_patch(const Mesh& probe_as_given, const Mesh& object_as_given, const Pose& pose,
                                         std::span<const ContactPair> pairs) {
  const auto given = static_cast<std::uint32_t>(std::min<std::size_t>(pairs.size(), UINT32_MAX));
  const Mesh& probe = joined(probe_as_given, 0);
  const Mesh& object = joined(object_as_given, 1);
  const Joined &jp = *joined_[0], &jo = *joined_[1];
  if (!jp.face_of.empty() || !jo.face_of.empty()) {  // a face written again is its first's
    named_pairs_.assign(pairs.begin(), pairs.end());
    for (ContactPair& q : named_pairs_) {
      if (q.probe < jp.face_of.size()) q.probe = jp.face_of[q.probe];
      if (q.object < jo.face_of.size()) q.object = jo.face_of[q.object];
    }
    std::sort(named_pairs_.begin(), named_pairs_.end());
    named_pairs_.erase(std::unique(named_pairs_.begin(), named_pairs_.end()), named_pairs_.end());
    pairs = named_pairs_;
  }
  ContactModel m = build_patch_joined(probe, object, pose, pairs);
  if (m.deepest_probe_vertex < jp.vertex_of.size()) m.deepest_probe_vertex = jp.vertex_of[m.deepest_probe_vertex];
  m.pairs = given;
  return m;
}

ContactModel ContactBuilder::build_patch_joined(const Mesh& probe, const Mesh& object, const Pose& pose,
                                                std::span<const ContactPair> pairs) {
  Back& b = back_for(object);
  if (!b.patch) return patch_->build(probe, object, pose, pairs);  // every part closed
  if (b.active && b.patch->has_history()) {                        // a contact on the back goes on, on the back
    ContactModel m = b.patch->build(probe, b.mesh, pose, pairs);
    if (!m.in_contact()) b.active = false;
    return m;
  }
  b.active = false;
  const bool going_on = patch_->has_history();
  ContactModel m = patch_->build(probe, object, pose, pairs);
  if (going_on || !m.in_contact()) return m;
  // A first contact: if it meets an open part, the side the probe is less deep on.
  const bool open_met = std::any_of(pairs.begin(), pairs.end(), [&](const ContactPair& p) {
    return p.object < b.open.size() && b.open[p.object] != 0;
  });
  if (!open_met) return m;
  ContactModel rear = b.patch->build(probe, b.mesh, pose, pairs);
  if (rear.in_contact() && rear.penetration_mm < m.penetration_mm) {
    patch_->reset();
    b.active = true;
    return rear;
  }
  b.patch->reset();
  return m;
}

ContactModel ContactBuilder::build(const Mesh& probe, const Mesh& object, const Pose& pose,
                                   std::span<const ContactPair> pairs) {
  ContactModel m = config_.model == ContactModelKind::paper ? build_paper(probe, object, pose, pairs)
                                                            : build_patch(probe, object, pose, pairs);
  m.kind = static_cast<std::uint32_t>(config_.model);
  ST_ASSERT(!m.in_contact() || std::abs(to_eigen(m.force_dir).norm() - 1.0) < 1e-9, "FD is a unit vector in contact");
  ST_ASSERT(std::isfinite(m.penetration_mm) && m.penetration_mm >= 0, "PD is finite and >= 0");
  ST_ASSERT(m.contacts == m.object_faces + m.probe_faces, "contacts = object faces + probe faces");
  return m;
}

namespace {
void sort_unique(std::vector<std::uint32_t>& v) {
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
}
}  // namespace

// Unit normal and centroid of face f, object-local; false when degenerate or non-finite.
bool face_frame(const Mesh& m, std::uint32_t f, Vec3& centroid, Vec3& normal) {
  const Tri& t = m.faces[f];
  const Vec3& a = m.local[t[0]];
  const Vec3& b = m.local[t[1]];
  const Vec3& c = m.local[t[2]];
  centroid = (a + b + c) / 3.0;
  const Vec3 n = (b - a).cross(c - a);
  const double longest2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  const double len = n.norm();
  if (!std::isfinite(len) || !(len > kDegenerateRel * longest2)) return false;
  normal = n / len;
  return true;
}

ContactModel ContactBuilder::build_paper(const Mesh& probe, const Mesh& object, const Pose& pose,
                                         std::span<const ContactPair> pairs) {
  ContactModel m;
  m.pose = to_pod(pose);
  m.pairs = static_cast<std::uint32_t>(std::min<std::size_t>(pairs.size(), UINT32_MAX));
  const bool pose_ok = pose.matrix().allFinite();
  if (!pose_ok) m.flags |= kBadInput;

  probe_faces_.clear();
  object_faces_.clear();
  for (const ContactPair& p : pairs) {
    const bool bad = p.probe >= probe.faces.size() || p.object >= object.faces.size();
    if (bad) {
      ++m.skipped_pairs;
      continue;
    }
    probe_faces_.push_back(p.probe);
    object_faces_.push_back(p.object);
  }
  if (m.skipped_pairs) m.flags |= kBadInput;
  sort_unique(probe_faces_);
  sort_unique(object_faces_);
  m.probe_faces = static_cast<std::uint32_t>(probe_faces_.size());
  m.object_faces = static_cast<std::uint32_t>(object_faces_.size());
  m.contacts = m.probe_faces + m.object_faces;

  // Distinct probe contact-face vertices, moved into object-local coordinates:
  // x_obj_local = R·local + (R·probe.origin + t - object.origin) (no large offsets in the sum).
  probe_vertices_.clear();
  for (std::uint32_t f : probe_faces_)
    for (std::uint32_t v : probe.faces[f])
      if (v < probe.local.size()) probe_vertices_.push_back(v);
  sort_unique(probe_vertices_);
  const Eigen::Matrix3d R = pose.linear();
  const Vec3 shift = R * probe.origin + pose.translation() - object.origin;
  probe_points_.clear();
  for (std::uint32_t v : probe_vertices_) probe_points_.push_back(R * probe.local[v] + shift);

  // Nearest (probe vertex, object face centroid) pair over non-degenerate object faces.
  double best = std::numeric_limits<double>::infinity();
  std::uint32_t best_face = UINT32_MAX;
  std::size_t best_vertex = 0;
  Vec3 best_centroid = Vec3::Zero(), best_normal = Vec3::Zero();
  Vec3 c, n;
  if (pose_ok) {
    for (std::uint32_t f : object_faces_) {
      if (!face_frame(object, f, c, n)) {
        ++m.degenerate_faces;
        continue;
      }
      for (std::size_t i = 0; i < probe_points_.size(); ++i) {
        const double d2 = (probe_points_[i] - c).squaredNorm();
        if (d2 < best) {  // strict: ties keep the lower face (outer loop ascending), then lower vertex
          best = d2;
          best_face = f;
          best_vertex = i;
          best_centroid = c;
          best_normal = n;
        }
      }
    }
  }
  if (m.degenerate_faces) m.flags |= kDegenerateSkipped;
  if (best_face == UINT32_MAX) {
    reset();  // zero usable contacts: the paper's "first contact" ends here
    return m;
  }

  m.flags |= kInContact;
  m.nearest_object_face = best_face;
  m.nearest_probe_vertex = probe_vertices_[best_vertex];
  m.force_dir = to_pod(best_normal);
  const Vec3& pv = probe_points_[best_vertex];
  m.contact_point = to_pod(pv - (pv - best_centroid).dot(best_normal) * best_normal + object.origin);
  m.pressure_point = m.contact_point;

  // First contact face: record at contact start; re-record when FD has turned too far from it.
  const double cos_limit = std::cos(config_.replane_angle_deg * 3.14159265358979323846 / 180.0);
  if (first_face_ == UINT32_MAX || first_normal_.dot(best_normal) < cos_limit) {
    first_face_ = best_face;
    first_point_ = best_centroid;
    first_normal_ = best_normal;
    m.flags |= kReplaned;
  }
  m.first_contact_face = first_face_;

  // PD: deepest probe contact vertex below the recorded plane.
  double pd = 0;
  std::size_t deepest = best_vertex;
  double deepest_depth = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < probe_points_.size(); ++i) {
    const double depth = (first_point_ - probe_points_[i]).dot(first_normal_);
    if (depth > deepest_depth) {
      deepest_depth = depth;
      deepest = i;
    }
  }
  pd = std::max(0.0, deepest_depth);
  m.penetration_mm = pd;
  m.deepest_probe_vertex = probe_vertices_[deepest];
  m.probe_point = to_pod(probe.origin + probe.local[probe_vertices_[deepest]]);
  // Local contact plane, normal FD, placed so the deepest vertex is PD below it at this pose.
  m.plane_point = to_pod(probe_points_[deepest] + pd * best_normal + object.origin);

  for (std::uint32_t f : object_faces_) {
    if (face_frame(object, f, c, n) && n.dot(best_normal) < 0) {
      m.flags |= kNormalsDisagree;
      break;
    }
  }
  return m;
}

}  // namespace st::geom
