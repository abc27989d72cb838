// SPDX-License-Identifier: BSD-3-Clause
// FCL peer: fcl::BVHModel<OBBRSSd> with fcl::collide and an unlimited contact count.
#include "fcl_peer.hpp"

#include <fcl/narrowphase/collision.h>
#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/narrowphase/detail/primitive_shape_algorithm/triangle_distance.h>

#include <algorithm>
#include <chrono>
#include <limits>

namespace st::bench {

namespace {
std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> build(const geom::Mesh& m) {
  std::vector<fcl::Vector3d> pts(m.local.begin(), m.local.end());
  std::vector<fcl::Triangle> tris;
  tris.reserve(m.faces.size());
  for (const geom::Tri& t : m.faces) tris.emplace_back(t[0], t[1], t[2]);
  auto model = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  model->beginModel(static_cast<int>(tris.size()), static_cast<int>(pts.size()));
  model->addSubModel(pts, tris);
  model->endModel();
  return model;
}
}  // namespace

struct FclPeer::Impl {
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> probe, object;
  geom::Vec3 probe_origin, object_origin;
};

FclPeer::FclPeer(const geom::Mesh& probe, const geom::Mesh& object) : impl_(std::make_unique<Impl>()) {
  const auto t0 = std::chrono::steady_clock::now();
  impl_->probe = build(probe);
  impl_->object = build(object);
  build_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  impl_->probe_origin = probe.origin;
  impl_->object_origin = object.origin;
}

FclPeer::~FclPeer() = default;

namespace {
// Same relative transform as ours: probe-local -> object-local.
fcl::Transform3d relative(const geom::Pose& pose, const geom::Vec3& probe_origin, const geom::Vec3& object_origin) {
  fcl::Transform3d rel = fcl::Transform3d::Identity();
  rel.linear() = pose.linear();
  rel.translation() = pose.linear() * probe_origin + pose.translation() - object_origin;
  return rel;
}
}  // namespace

double FclPeer::tri_distance(const geom::Pose& pose, std::uint32_t pf, std::uint32_t of) const {
  const fcl::Transform3d rel = relative(pose, impl_->probe_origin, impl_->object_origin);
  const auto& P = *impl_->probe;
  const auto& O = *impl_->object;
  const fcl::Triangle& tp = P.tri_indices[pf];
  const fcl::Triangle& to = O.tri_indices[of];
  fcl::Vector3d a[3], b[3], x, y;
  for (int k = 0; k < 3; ++k) {
    a[k] = rel * P.vertices[tp[k]];
    b[k] = O.vertices[to[k]];
  }
  return fcl::detail::TriangleDistance<double>::triDistance(a, b, x, y);
}

std::vector<std::pair<std::uint32_t, std::uint32_t>> FclPeer::collide(const geom::Pose& pose, double* query_s) const {
  const fcl::Transform3d rel = relative(pose, impl_->probe_origin, impl_->object_origin);
  fcl::CollisionObjectd a(impl_->probe, rel);
  fcl::CollisionObjectd b(impl_->object, fcl::Transform3d::Identity());
  fcl::CollisionRequestd req(std::numeric_limits<int>::max() / 2, false);
  fcl::CollisionResultd res;
  const auto t0 = std::chrono::steady_clock::now();
  fcl::collide(&a, &b, req, res);
  if (query_s) *query_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::vector<fcl::Contactd> contacts;
  res.getContacts(contacts);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
  out.reserve(contacts.size());
  for (const auto& c : contacts) out.emplace_back(std::uint32_t(c.b1), std::uint32_t(c.b2));
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

double fcl_build_seconds(const geom::Mesh& mesh) {
  const auto t0 = std::chrono::steady_clock::now();
  auto m = build(mesh);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace st::bench
