// The app's side of distribution: start N in-process workers (inproc://, the embedded default)
// or connect to worker daemons, deal the object's layer-n sphere blocks over them and wait until
// every worker holds its share. Used by `query --workers/--connect` and by `run`.
#pragma once
#include <chrono>
#include <memory>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "geom/sphere_tree.hpp"
#include "net/local_workers.hpp"
#include "net/scatter_gather.hpp"

namespace st::app {

/// How to reach the workers.
struct FleetSpec {
  int workers = 0;                     ///< in-process workers (ignored when endpoints are given)
  std::vector<std::string> endpoints;  ///< worker daemons
  std::uint32_t layer = 2, block_size = 1;  ///< distribution: sphere layer, layer spheres per block
  std::uint32_t leaf_faces = geom::DefaultTreeParams().leaf_faces;  ///< tree knob sent to workers
  std::uint32_t miss_limit = 3;        ///< missed deadlines before a worker is marked down
  std::chrono::milliseconds ready_timeout{30000};  ///< time allowed for the first upload
};

/// A running fleet: its context, the in-process workers (if any) and the client.
struct Fleet {
  zmq::context_t ctx{1};
  std::unique_ptr<net::LocalWorkers> local;
  std::unique_ptr<net::ScatterGather> client;
  std::uint32_t blocks = 0;       ///< blocks dealt
  std::string description;        ///< "2 in-process workers" / "3 daemons"
  /// Workers currently up (not marked down).
  int up() const;
};

/// Starts the fleet and waits until every worker holds its blocks; errors say which step failed.
Result<std::unique_ptr<Fleet>> start_fleet(const FleetSpec& spec, const geom::Mesh& probe, const geom::Mesh& object,
                                           const geom::SphereTree& object_tree);

}  // namespace st::app
