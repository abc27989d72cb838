// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// The production CollisionBackend: the worker builds sphere trees (SphereTree) over the whole
/// probe and over its share of the object, and answers each Query with collide() — exact, so the
/// union over workers equals the single-process result. Also cuts an object's sphere tree into
/// the layer-n blocks that ScatterGather deals block-cyclically (paper §3.4).
#pragma once
#include <spheretouch/abi.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/backend.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Leaves piled at one spot (geom::crowding) past which a block set is refused at load: the
/// model set's meshes (hand to armadillo_L2, leaf_faces 8 to 64) have 22 to 34; faces piled on
/// each other, which make a query cost N² triangle tests, have as many as the pile has leaves.
inline constexpr std::uint32_t kDefaultMaxCrowding = 256;

/// Factory of sphere-tree backends (the daemon's and the in-process workers' default). A worker
/// builds one subtree per block of its share; `per_block` false builds one tree over the whole
/// share instead (what workers did before; kept to measure the difference, bench scale --share-tree).
/// A set whose probe or share piles more than `max_crowding` leaves at one spot is refused (0: no check).
/// `coherent` (the default) answers through the coherent collider (geom::CoherentCollider, cache
/// <= kCoherentCacheBytes): along a haptic slide it reuses the last round's certificates; false
/// answers every query from scratch (what a query at an unrelated pose costs; bench scale's shares).
BackendFactory tree_backend_factory(bool per_block = true, std::uint32_t max_crowding = kDefaultMaxCrowding,
                                    bool coherent = true);

/// The object's faces grouped by the partition of `tree`'s layer `layer` into runs of
/// `block_size` consecutive layer spheres (geom::make_partition): blocks[b] = faces of block b.
Result<Blocks> tree_blocks(const geom::SphereTree& tree, std::uint32_t layer, std::uint32_t block_size);

}  // namespace st::net
