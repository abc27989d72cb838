// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/contact.hpp>: the contact model next to the collision query (as Coal pairs
/// collide() with computeContactPatch()): ComputeContactPatch turns the pairs a ComputeCollision
/// found into a ContactModel (FD, PD, the local contact plane; the force law makes it a force),
/// keeping the model's history between rounds. Core library (Eigen only).
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/collide.hpp>
#include <spheretouch/geom/contact.hpp>

namespace st {
inline namespace SPHERETOUCH_ABI {

using geom::ContactConfig;
using geom::ContactModel;

/// The contact model of one (probe, object) pair, round after round: the patch model by default
/// (depth and direction continuous in the pose), the paper's with ContactConfig::model. Not
/// thread-safe: one per thread and pair, like ComputeCollision.
class ComputeContactPatch {
 public:
  /// `config` must pass geom::check(config) (asserted where asserts are checked).
  explicit ComputeContactPatch(ContactConfig config = geom::DefaultContactConfig()) : builder_(config) {}
  /// The model of `collision` (its pairs, found at `relative`: probe frame -> object frame; use
  /// the same pose the query ran at). Object frame, except probe_point (probe frame).
  ContactModel operator()(const Body& probe, const Body& object, const Pose& relative, const CollisionResult& collision) {
    return builder_.build(probe.mesh(), object.mesh(), relative, collision.pairs);
  }
  /// The model of what `pair` found at its last query at `relative`.
  ContactModel operator()(ComputeCollision& pair, const Pose& relative, const CollisionResult& collision) {
    return (*this)(pair.probe(), pair.object(), relative, collision);
  }
  /// Forgets the history (as if contact had ended).
  void reset() { builder_.reset(); }
  /// The builder's knobs.
  const ContactConfig& config() const { return builder_.config(); }

 private:
  geom::ContactBuilder builder_;
};

}  // namespace SPHERETOUCH_ABI
}  // namespace st
