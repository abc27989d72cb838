// SPDX-License-Identifier: BSD-3-Clause
// Fleet start-up: see distributed.hpp.
#include <spheretouch/engine/distributed.hpp>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <map>

#include <spheretouch/net/endpoint_probe.hpp>
#include <spheretouch/net/tree_backend.hpp>
#include <spheretouch/net/worker_config.hpp>

namespace st::inline SPHERETOUCH_ABI::engine {

int Fleet::up() const {
  int n = 0;
  for (const auto& c : clients)
    if (c) {
      for (const net::WorkerStatus& w : c->workers()) n += w.up;
      break;
    }
  return n;
}

namespace {

/// Seconds as the user reads them ("2 s", "0.5 s").
std::string seconds(std::chrono::milliseconds ms) {
  char b[32];
  std::snprintf(b, sizeof b, "%g s", double(ms.count()) / 1000.0);
  return b;
}

/// What to do about a probe's finding, for the error message.
std::string advice(const net::ProbeResult& p, const FleetSpec& spec) {
  switch (p.outcome) {
    case net::ProbeOutcome::auth_refused:
      return "; this client's public key " + spec.curve.client.public_z85 +
             " is not in the worker's [curve] allowed_clients (or allowed_clients_files): add it there, or use a "
             "client key that is (the worker logs the refusal)";
    case net::ProbeOutcome::security_mismatch:
      return spec.curve.enabled() ? "; remove the client keys, or configure the worker's [curve]"
                                  : "; give the workers' public key and a client key pair (--server-key FILE "
                                    "--client-key PREFIX, or [workers] server_key / client_key)";
    default:
      return "";
  }
}

}  // namespace

Result<ClientCurve> load_client_curve(const std::string& server_key_file, const std::string& client_prefix,
                                      const std::string& server_what, const std::string& client_what) {
  ClientCurve c;
  if (server_key_file.empty() && client_prefix.empty()) return c;
  if (server_key_file.empty()) return fail(client_what, " is given but ", server_what, " is not: CURVE needs both");
  if (client_prefix.empty()) return fail(server_what, " is given but ", client_what, " is not: CURVE needs both");
  Result<std::string> server = net::read_public_key(server_key_file);
  if (!server) return fail(server_what, ": ", server.error());
  Result<net::CurveKeyPair> client = net::read_key_pair(client_prefix);
  if (!client) return fail(client_what, ": ", client.error());
  c.server_public = std::move(server).value();
  c.client = std::move(client).value();
  return c;
}

Status wait_for_fleet(Fleet& fleet, const FleetSpec& spec, const net::ScatterConfig& cfg) {
  for (const std::unique_ptr<net::ScatterGather>& c : fleet.clients)
    if (c)
      if (Status st = wait_for_client(fleet, *c, spec, cfg); !st) return st;
  return Ok{};
}

Status wait_for_client(Fleet& fleet, net::ScatterGather& client, const FleetSpec& spec, const net::ScatterConfig& cfg) {
  const auto start = net::Clock::now();
  const auto until = start + spec.ready_timeout;
  // First wait briefly: a daemon that has not said Hello by then is probed, and a refused key or
  // a security mismatch ends the start now instead of after ready_timeout.
  if (client.wait_ready(std::min(until, start + spec.hello_timeout))) return Ok{};
  // A daemon whose messages this client cannot read (another protocol version): waiting cannot help.
  for (const net::WorkerStatus& w : client.workers())
    if (w.epoch == 0 && !w.unreadable.empty())
      return fail("worker ", w.endpoint, " answers with messages this client cannot read (", w.unreadable,
                  "): a spheretouch-worker of another version? Upgrade the daemons and the clients together");
  std::map<std::string, net::ProbeResult> probed;
  auto probe_silent = [&] {
    for (const net::WorkerStatus& w : client.workers())
      if (w.epoch == 0 && !fleet.local)
        probed[w.endpoint] = net::probe_endpoint(fleet.ctx, w.endpoint, cfg.curve_server_public, cfg.curve_public,
                                                 cfg.curve_secret, std::chrono::milliseconds(2000));
  };
  probe_silent();
  for (const auto& [ep, p] : probed)
    if (p.definitive())
      return fail("worker ", ep, " did not answer Hello within ", seconds(spec.hello_timeout), ": ", p.detail,
                  advice(p, spec));
  if (spec.note)
    for (const auto& [ep, p] : probed)
      spec.note("worker " + ep + " has not answered Hello after " + seconds(spec.hello_timeout) + " (" + p.detail +
                "); waiting up to " + seconds(spec.ready_timeout));
  if (client.wait_ready(until)) return Ok{};
  probed.clear();
  probe_silent();
  std::string who;
  for (const net::WorkerStatus& w : client.workers()) {
    if (w.holds_target) continue;
    who += (who.empty() ? "" : "; ") + w.endpoint;
    if (auto it = probed.find(w.endpoint); it != probed.end())
      who += " never answered Hello: " + it->second.detail + advice(it->second, spec);
    else if (!w.refused.empty())
      who += " refused its block set: " + w.refused;
    else
      who += " answered but did not acknowledge its block set";
  }
  return fail("workers did not load their blocks within ", seconds(spec.ready_timeout), ": ", who);
}

Result<std::unique_ptr<Fleet>> start_fleet(const FleetSpec& spec, const geom::Mesh& probe, const geom::Mesh& object,
                                           const geom::SphereTree& object_tree) {
  const FleetObject one[] = {FleetObject{&object, &object_tree}};
  return start_fleet(spec, probe, one);
}

Result<std::unique_ptr<Fleet>> start_fleet(const FleetSpec& spec, const geom::Mesh& probe,
                                           std::span<const FleetObject> objects) {
  if (objects.empty()) return fail("distribution: no objects");
  auto fleet = std::make_unique<Fleet>();
  const std::size_t nworkers = spec.endpoints.empty() ? std::size_t(std::max(spec.workers, 0)) : spec.endpoints.size();
  // Each object's split: the automatic pick for that object and worker count (either knob may be
  // pinned by the scene; the other is chosen).
  std::vector<net::Blocks> object_blocks;
  for (std::size_t k = 0; k < objects.size(); ++k) {
    const std::string who = objects.size() > 1 ? "object " + std::to_string(k + 1) + ": " : std::string();
    std::uint32_t layer = spec.layer, block_size = spec.block_size;
    std::string split;
    if (nworkers > 0 && (layer == geom::kFree || block_size == 0)) {
      geom::SplitModelConfig model;
      model.contact_radius = spec.contact_radius;
      Result<geom::SplitChoice> pick =
          geom::choose_split(*objects[k].tree, std::uint32_t(nworkers), spec.mapping, model, layer, block_size);
      if (!pick && objects.size() > 1 && objects[k].tree->num_leaves() < nworkers) {
        // An object of fewer leaves than workers (a box of 12 faces) is not worth a round trip:
        // the collision thread answers it (clients[k] stays null).
        object_blocks.emplace_back();
        ++fleet->local_objects;
        continue;
      }
      if (!pick) return fail("distribution: ", who, pick.error());
      layer = pick.value().layer;
      block_size = pick.value().block_size;
      split = pick.value().why + " (automatic; set [tree] layer and block_size to override)";
    }
    if (layer == geom::kFree) layer = 2;  // no workers: nothing is dealt
    if (block_size == 0) block_size = 1;
    Result<net::Blocks> blocks = net::tree_blocks(*objects[k].tree, layer, block_size);
    if (!blocks) return fail("distribution: ", who, blocks.error());
    const auto nblocks = static_cast<std::uint32_t>(blocks.value().size());
    if (split.empty())
      split = "layer " + std::to_string(layer) + ", block size " + std::to_string(block_size) + ": " +
              std::to_string(nblocks) + " blocks, " + geom::to_string(spec.mapping) + " over " +
              std::to_string(nworkers) + " workers (set in the scene)";
    if (nblocks < nworkers)
      return fail("distribution: ", who, "layer ", layer, " gives ", nblocks, " blocks for ", nworkers,
                  " workers (choose a deeper layer or a smaller block size)");
    fleet->blocks += nblocks;
    if (k == 0) fleet->split = split;
    object_blocks.push_back(std::move(blocks).value());
  }
  if (objects.size() > 1)
    fleet->split += "; " + std::to_string(objects.size()) + " objects, " + std::to_string(fleet->blocks) +
                    " blocks in all, each object's own block set over the same workers" +
                    (fleet->local_objects ? " (" + std::to_string(fleet->local_objects) +
                                                " too small to split, answered by the collision thread)"
                                          : std::string());
  net::ScatterConfig cfg;
  cfg.mapping = spec.mapping;
  cfg.miss_limit = spec.miss_limit;
  cfg.assist_blocks = spec.assist_blocks;
  cfg.replicas = spec.replicas;
  cfg.leaf_faces = spec.leaf_faces;
  cfg.distinct_faces = spec.distinct_faces;
  if (spec.curve.enabled() && spec.endpoints.empty())
    return fail(
        "CURVE keys (server key, client key) are for worker daemons; in-process workers need none "
        "(give the daemons' endpoints with --connect or [workers] endpoints)");
  if (!spec.endpoints.empty()) {
    cfg.endpoints = spec.endpoints;
    if (spec.curve.enabled()) {
      cfg.curve_server_public = spec.curve.server_public;
      cfg.curve_public = spec.curve.client.public_z85;
      cfg.curve_secret = spec.curve.client.secret_z85;
    }
    fleet->description = std::to_string(spec.endpoints.size()) + " worker daemon" + (spec.endpoints.size() == 1 ? "" : "s");
    // Plaintext to another host: say so (the daemons refuse it unless started --insecure).
    if (!spec.curve.enabled())
      for (const std::string& ep : spec.endpoints)
        if (!net::is_local_endpoint(ep))
          std::fprintf(stderr,
                       "warning: %s is not a loopback or ipc:// endpoint and no CURVE keys are set: poses, block "
                       "sets and results cross the network in plaintext, unauthenticated (set server_key and "
                       "client_key, docs/user-guide/security.md, \"Securing a fleet\")\n",
                       ep.c_str());
  } else {
    if (spec.workers < 1) return fail("distribution: no workers (use --workers N or --connect EP,...)");
    // A tag unique to this fleet keeps inproc names apart when several fleets share a process.
    static std::atomic<int> fleets{0};
    const std::string tag = std::to_string(::getpid()) + "-" + std::to_string(fleets++);
    // Every object's sets stay in memory (its own share, its standby copies with replicas, and a
    // reassigned variant), however long the probe stays away from it.
    net::WorkerConfig base;
    base.max_sets = std::max<std::uint32_t>(base.max_sets, std::uint32_t((spec.replicas ? 3 : 2) * objects.size() + 1));
    if (objects.size() > 1) base.idle_set_ttl = std::chrono::milliseconds(0);
    Result<std::unique_ptr<net::LocalWorkers>> lw = net::LocalWorkers::start(
        fleet->ctx, spec.workers, net::tree_backend_factory(true, net::kDefaultMaxCrowding, spec.coherent),
        [&](int i) { return net::inproc_endpoint(i, tag); }, base);
    if (!lw) return fail("in-process workers: ", lw.error());
    fleet->local = std::move(lw).value();
    cfg.endpoints = fleet->local->endpoints();
    fleet->description = std::to_string(spec.workers) + " in-process worker" + (spec.workers == 1 ? "" : "s");
  }
  if (spec.replicas) fleet->description += ", every block on two workers (replicated deal)";
  if (spec.assist_blocks > 0)
    fleet->description += " + client assist (" + std::to_string(spec.assist_blocks) + " blocks)";
  for (std::size_t k = 0; k < objects.size(); ++k) {
    if (object_blocks[k].empty()) {  // answered by the collision thread
      fleet->clients.emplace_back();
      continue;
    }
    cfg.object = std::uint32_t(k);  // its block sets, Queries and Results name it
    Result<std::unique_ptr<net::ScatterGather>> sg =
        net::ScatterGather::create(fleet->ctx, cfg, probe, *objects[k].mesh, std::move(object_blocks[k]));
    if (!sg) {
      net::wipe_secret(cfg.curve_secret);
      return fail("scatter-gather: ", sg.error());
    }
    fleet->clients.push_back(std::move(sg).value());
  }
  const Status ready = wait_for_fleet(*fleet, spec, cfg);  // probes silent workers with the key
  net::wipe_secret(cfg.curve_secret);                      // the client keeps its own copy
  if (!ready) return Error{ready.error()};
  return fleet;
}

}  // namespace st::engine
