// SPDX-License-Identifier: BSD-3-Clause
// The coherent collider's bookkeeping (coherent.hpp). Its round, which needs the per-ISA kernels,
// is CoherentCollider::collide in collide.cpp (coherent_traversal.inl).
#include <spheretouch/geom/coherent.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

namespace st::inline SPHERETOUCH_ABI::geom {

bool CoherentCollider::same_setup(const SphereTree& probe_tree, const SphereTree& object_tree,
                                  const CollideConfig& options) const {
  if (probe_key_ != probe_tree.nodes.data() || probe_hash_ != probe_tree.mesh_hash ||
      object_key_ != object_tree.nodes.data() || object_hash_ != object_tree.mesh_hash ||
      restrict_ != options.restrict_object)
    return false;
  return !restrict_ || std::equal(roots_.begin(), roots_.end(), options.object_roots.begin(), options.object_roots.end());
}

std::uint64_t CoherentCollider::setup_key(const SphereTree& probe_tree, const SphereTree& object_tree,
                                          const CollideConfig& options) {
  // FNV-1a over the words same_setup() compares.
  std::uint64_t h = 0xcbf29ce484222325ull;
  const auto mix = [&h](std::uint64_t v) {
    for (int k = 0; k < 8; ++k, v >>= 8) h = (h ^ (v & 0xff)) * 0x100000001b3ull;
  };
  mix(reinterpret_cast<std::uintptr_t>(probe_tree.nodes.data()));
  mix(probe_tree.mesh_hash);
  mix(reinterpret_cast<std::uintptr_t>(object_tree.nodes.data()));
  mix(object_tree.mesh_hash);
  mix(options.restrict_object ? 1 : 0);
  if (options.restrict_object) {
    mix(options.object_roots.size());
    for (std::uint32_t r : options.object_roots) mix(r);
  }
  return h | 1;  // never 0 (0: nothing pending)
}

void CoherentCollider::adopt(const SphereTree& probe_tree, const SphereTree& object_tree, const CollideConfig& options) {
  reset();
  probe_key_ = probe_tree.nodes.data();
  probe_hash_ = probe_tree.mesh_hash;
  object_key_ = object_tree.nodes.data();
  object_hash_ = object_tree.mesh_hash;
  restrict_ = options.restrict_object;
  roots_.assign(options.object_roots.begin(), options.object_roots.end());
  double sum = 0;
  std::size_t leaves = 0;
  for (const SphereNode& n : probe_tree.nodes)
    if (n.leaf) sum += n.radius, ++leaves;
  leaf_radius_ = leaves > 0 ? sum / double(leaves) : 0.0;
  max_step_ = config_.max_step > 0 ? config_.max_step : leaf_radius_ / 64;
  const double root = probe_tree.nodes.empty() ? 0.0 : double(probe_tree.nodes[0].radius);
  const int e = std::isfinite(root) && root > 0 ? std::ilogb(root) - 40 : -1000;
  path_quantum_ = std::ldexp(1.0, e);
  path_per_quantum_ = std::ldexp(1.0, -e);
}

void CoherentCollider::drop() {
  have_front_ = false;
  leaf_entries_ = 0;
  garbage_ = 0;
  near_.radius = -1;
  front_.clear();
  groups_.clear();
  glevel_.clear();
  old_groups_.clear();
  dead_ = 0;
  cands_.clear();
}

void CoherentCollider::compact_groups() {
  if (dead_ < 1024 || 2 * dead_ < groups_.size()) return;
  std::erase_if(groups_, [](const detail::FrontEntry& e) { return e.kind == detail::kDead; });
  glevel_.clear();
  for (const detail::FrontEntry& g : groups_) glevel_.push_back(g.level);
  dead_ = 0;
}

void CoherentCollider::compact() {
  next_cands_.clear();
  for (detail::FrontEntry& e : front_) {
    if (e.kind != detail::kLeafPair) continue;
    const auto at = static_cast<std::uint32_t>(next_cands_.size());
    next_cands_.insert(next_cands_.end(), cands_.begin() + e.arg, cands_.begin() + e.arg + e.count);
    e.arg = at;
  }
  cands_.swap(next_cands_);
  garbage_ = 0;
}

void CoherentCollider::reset() {
  drop();
  round_ = 0;
  plain_until_ = 0;
  plain_ns_ = coherent_ns_ = 0;
  timed_round_ = 0;
  timed_pairs_ = last_pairs_ = 0;
  rebuild_ns_ = 0;
  rebuild_round_ = 0;
  rebuild_pairs_ = 0;
  coherent_rounds_ = spells_ = 0;
  have_last_ = false;
  step_ = 0;
  for (detail::CertPose& p : poses_) p.round = ~0u;
  last_cached_ = ~0u;
  path_ = 0;
  for (detail::PoseDelta& d : deltas_) d.key = ~std::uint64_t{0};  // rounds count from 0 again
}

double CoherentCollider::moved_since(const RelTransform& a, const RelTransform& b, const Vec3& c, double r) {
  const Eigen::Matrix3d D = b.R - a.R;
  return (D * c + (b.t - a.t)).norm() + D.norm() * r;
}

void CoherentCollider::note_contact(const Mesh& probe, const CollideResult& result) {
  near_.radius = -1;
  const std::size_t n = result.pairs.size();
  if (n == 0) return;
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  const std::size_t stride = std::max<std::size_t>(1, n / 64);  // a sample: this only steers the policy
  for (std::size_t i = 0; i < n; i += stride) {
    const Vec3& v = probe.local[probe.faces[result.pairs[i].probe][0]];
    lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  }
  near_.centre = 0.5 * (lo + hi);
  near_.radius = 0.5 * (hi - lo).norm() + leaf_radius_;
}

std::uint32_t CoherentCollider::build_budget() const {
  if (!have_front_) return 0;
  const double share = std::min(0.25, 0.02 * std::pow(1.5, double(std::min<std::uint32_t>(ramp_, 16))));
  return std::max<std::uint32_t>(4, static_cast<std::uint32_t>(std::ceil(share * leaf_entries_)));
}

double CoherentCollider::choose_reach() const {
  if (config_.reach > 0) return config_.reach;
  return std::clamp(8 * step_, leaf_radius_ / 16, leaf_radius_ / 8);
}

std::size_t CoherentCollider::bytes() const {
  auto b = [](const auto& v) { return v.capacity() * sizeof(v[0]); };
  return b(front_) + b(next_front_) + b(groups_) + b(glevel_) + b(old_groups_) + b(cands_) + b(next_cands_) +
         b(leaf_index_) + b(roots_) + scratch_.bytes();
}

}  // namespace st::geom
