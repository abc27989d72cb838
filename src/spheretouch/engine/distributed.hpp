// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// <spheretouch/engine/distributed.hpp>: the client's side of distribution. Start N in-process
/// workers (inproc://, the embedded default) or connect to worker daemons, deal the object's
/// layer-n sphere blocks over them and wait until every worker holds its share; with CURVE keys
/// for daemons that require them, and a clear error (endpoint, reason, what to fix) when a daemon
/// refuses this client. Used by `query --workers/--connect` and by RunEngine.
#pragma once
#include <spheretouch/abi.hpp>
#include <chrono>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/geom/partition.hpp>
#include <spheretouch/geom/sphere_tree.hpp>
#include <spheretouch/net/curve_keys.hpp>
#include <spheretouch/net/local_workers.hpp>
#include <spheretouch/net/scatter_gather.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

/// A client's CURVE settings: the workers' public key and this client's key pair, Z85.
struct ClientCurve {
  std::string server_public;  ///< the workers' (fleet's) public key; empty: no CURVE
  net::CurveKeyPair client;   ///< this client's pair; its public key is in the workers' allow-list
  bool enabled() const { return !server_public.empty(); }  ///< keys were given
};

/// Reads a client's CURVE settings from the workers' public key file and this client's PREFIX
/// (PREFIX.key, mode 0600, and PREFIX.pub if present). Both or neither: two empty paths give
/// plain settings. Errors name the file and `server_what` / `client_what` (the flag or field).
Result<ClientCurve> load_client_curve(const std::string& server_key_file, const std::string& client_prefix,
                                      const std::string& server_what, const std::string& client_what);

/// How to reach the workers.
struct FleetSpec {
  int workers = 0;                     ///< in-process workers (ignored when endpoints are given)
  std::vector<std::string> endpoints;  ///< worker daemons
  /// Distribution: the sphere layer dealt in blocks; geom::kFree = automatic (geom::choose_split
  /// for this object and worker count, contact regions of contact_radius).
  std::uint32_t layer = geom::kFree;
  std::uint32_t block_size = 0;                         ///< layer spheres per block; 0 = automatic (with the layer)
  geom::Mapping mapping = geom::Mapping::block_cyclic;  ///< how blocks are dealt
  double contact_radius = 10;                           ///< mm, for the automatic split
  std::uint32_t leaf_faces = geom::DefaultTreeConfig().leaf_faces;  ///< tree knob sent to workers
  std::uint32_t miss_limit = 3;                                     ///< missed deadlines before a worker is marked down
  std::uint32_t assist_blocks = 0;  ///< blocks the client answers itself each round (net::ScatterConfig::assist_blocks)
  bool coherent = true;   ///< in-process workers answer through the coherent collider (daemons: their own config)
  bool replicas = false;  ///< every block on two workers, dealt by the work reported (net::ScatterConfig::replicas)
  /// each round's distinct faces (net::ScatterConfig::distinct_faces): the run, which counts its
  /// contacts in its contact model, turns them off
  bool distinct_faces = true;
  std::chrono::milliseconds ready_timeout{30000};  ///< time allowed for the first upload
  /// A daemon silent this long is probed: a refused CURVE key or a security mismatch fails the
  /// start at once (waiting cannot help); anything else waits out ready_timeout.
  std::chrono::milliseconds hello_timeout{2000};
  ClientCurve curve;  ///< CURVE keys for worker daemons (empty: plain)
  /// Progress notes while the start waits (a daemon still silent after hello_timeout); may be empty.
  std::function<void(const std::string&)> note;
};

/// One object to deal over the fleet.
struct FleetObject {
  const geom::Mesh* mesh = nullptr;        ///< its mesh (file coordinates)
  const geom::SphereTree* tree = nullptr;  ///< its sphere tree
};

/// A running fleet: its context, the in-process workers (if any) and one client per object.
/// Every object's blocks are dealt over the same workers, each object's as its own block set
/// (content-addressed, so a worker holds the objects' sets side by side): clients[k] answers for
/// object k.
struct Fleet {
  zmq::context_t ctx{1};                     ///< the fleet's ZeroMQ context (inproc:// needs one shared)
  std::unique_ptr<net::LocalWorkers> local;  ///< the in-process workers; null with daemons
  std::vector<std::unique_ptr<net::ScatterGather>> clients;  ///< per object: round() per pose
  net::ScatterGather& client() { return *clients.front(); }  ///< the first object's client
  /// Objects of fewer sphere-tree leaves than workers (several objects only): not dealt, their
  /// clients[k] is null and the collision thread answers them.
  std::uint32_t local_objects = 0;
  std::uint32_t blocks = 0;  ///< blocks dealt (summed over objects)
  std::string description;   ///< "2 in-process workers" / "3 daemons"
  std::string split;  ///< how the object was split and why ("layer 3, block size 1: ..."; of several: the first's)
  /// Workers currently up (not marked down).
  int up() const;
};

/// Waits until every worker of a started fleet holds its blocks (every object's). A daemon silent after
/// hello_timeout is probed (net::probe_endpoint); a refused CURVE key or a security mismatch
/// fails at once, naming the endpoint and what to fix; otherwise it waits out ready_timeout and
/// says, per worker, what went wrong.
Status wait_for_fleet(Fleet& fleet, const FleetSpec& spec, const net::ScatterConfig& cfg);
/// The same for one client of it.
Status wait_for_client(Fleet& fleet, net::ScatterGather& client, const FleetSpec& spec, const net::ScatterConfig& cfg);

/// Starts the fleet and waits until every worker holds its blocks; errors say which step failed.
Result<std::unique_ptr<Fleet>> start_fleet(const FleetSpec& spec, const geom::Mesh& probe, const geom::Mesh& object,
                                           const geom::SphereTree& object_tree);
/// The same for a scene of several objects: each object split (automatic or the spec's layer and
/// block size) and dealt over the same workers. In-process workers keep every object's sets
/// (max_sets grows with the objects, no idle expiry); daemons need [worker] max_sets of at least
/// objects + 2 and an idle_set_ttl longer than the time between touches of an object.
Result<std::unique_ptr<Fleet>> start_fleet(const FleetSpec& spec, const geom::Mesh& probe,
                                           std::span<const FleetObject> objects);

}  // namespace st::engine
