// SPDX-License-Identifier: BSD-3-Clause
// Shared by the net suites: small generated scenes, real-mesh scenes, and contact poses.
#pragma once
#include <random>
#include <vector>

#include <spheretouch/geom/mesh_io.hpp>
#include <spheretouch/geom/primitives.hpp>
#include <spheretouch/net/block_set.hpp>
#include <spheretouch/net/worker_service.hpp>
#include "test_util.hpp"

namespace st::test {

/// A worker service (WorkerService::create), or the test stops with its error.
inline std::unique_ptr<net::WorkerService> make_worker(zmq::context_t& ctx, net::WorkerConfig cfg,
                                                       net::BackendFactory factory) {
  auto w = net::WorkerService::create(ctx, std::move(cfg), std::move(factory));
  REQUIRE_MESSAGE(w.ok(), w.error());
  return std::move(w).value();
}

/// Probe, object and the object's blocks.
struct NetScene {
  geom::Mesh probe, object;
  net::Blocks blocks;
};

/// A capsule fingertip against an icosphere of 20·freq² faces (no files needed).
inline NetScene small_scene(int freq = 8, std::uint32_t faces_per_block = 32) {
  NetScene s{geom::make_capsule(4.0, 10.0, 12), geom::make_icosphere(30.0, freq), {}};
  s.blocks = net::spatial_blocks(s.object, faces_per_block);
  return s;
}

/// A real probe against a real object from the model set.
inline NetScene model_scene(const std::string& probe, const std::string& object, std::uint32_t faces_per_block) {
  auto p = geom::load_mesh(model(probe));
  REQUIRE_MESSAGE(p.ok(), p.error());
  auto o = geom::load_mesh(model(object));
  REQUIRE_MESSAGE(o.ok(), o.error());
  NetScene s{std::move(p.value().mesh), std::move(o.value().mesh), {}};
  s.blocks = net::spatial_blocks(s.object, faces_per_block);
  return s;
}

/// Poses that put the probe's centre on object vertices, randomly rotated: many contacts.
/// The last pose is far away (no contacts).
inline std::vector<geom::Pose> contact_poses(const NetScene& s, int n, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::vector<geom::Pose> v;
  for (int i = 0; i < n; ++i) {
    const geom::Vec3 at = s.object.vertex(static_cast<std::uint32_t>(rng() % s.object.num_vertices()));
    Eigen::Quaterniond q(std::normal_distribution<double>()(rng), std::normal_distribution<double>()(rng),
                         std::normal_distribution<double>()(rng), std::normal_distribution<double>()(rng));
    geom::Pose p = geom::Pose::Identity();
    p.linear() = q.normalized().toRotationMatrix();
    p.translation() = at - p.linear() * s.probe.origin;
    v.push_back(p);
  }
  geom::Pose far = geom::Pose::Identity();
  far.translation() = geom::Vec3(1e4, 0, 0);
  v.push_back(far);
  return v;
}

}  // namespace st::test
