// Fleet start-up: see distributed.hpp.
#include "app/distributed.hpp"

#include <unistd.h>

#include "net/tree_backend.hpp"

namespace st::app {

int Fleet::up() const {
  int n = 0;
  for (const net::WorkerStatus& w : client->workers()) n += w.up;
  return n;
}

Result<std::unique_ptr<Fleet>> start_fleet(const FleetSpec& spec, const geom::Mesh& probe, const geom::Mesh& object,
                                           const geom::SphereTree& object_tree) {
  auto fleet = std::make_unique<Fleet>();
  Result<net::Blocks> blocks = net::tree_blocks(object_tree, spec.layer, spec.block_size);
  if (!blocks) return fail("distribution: ", blocks.error());
  fleet->blocks = static_cast<std::uint32_t>(blocks.value().size());
  net::ScatterConfig cfg;
  cfg.miss_limit = spec.miss_limit;
  cfg.leaf_faces = spec.leaf_faces;
  if (!spec.endpoints.empty()) {
    cfg.endpoints = spec.endpoints;
    fleet->description = std::to_string(spec.endpoints.size()) + " worker daemon" + (spec.endpoints.size() == 1 ? "" : "s");
  } else {
    if (spec.workers < 1) return fail("distribution: no workers (use --workers N or --connect EP,...)");
    // A tag unique to this fleet keeps inproc names apart when several fleets share a process.
    static std::atomic<int> fleets{0};
    const std::string tag = std::to_string(::getpid()) + "-" + std::to_string(fleets++);
    Result<std::unique_ptr<net::LocalWorkers>> lw = net::LocalWorkers::start(
        fleet->ctx, spec.workers, net::tree_backend_factory(), [&](int i) { return net::inproc_endpoint(i, tag); });
    if (!lw) return fail("in-process workers: ", lw.error());
    fleet->local = std::move(lw).value();
    cfg.endpoints = fleet->local->endpoints();
    fleet->description = std::to_string(spec.workers) + " in-process worker" + (spec.workers == 1 ? "" : "s");
  }
  if (fleet->blocks < cfg.endpoints.size())
    return fail("distribution: layer ", spec.layer, " gives ", fleet->blocks, " blocks for ", cfg.endpoints.size(),
                " workers (choose a deeper layer or a smaller block size)");
  Result<std::unique_ptr<net::ScatterGather>> sg =
      net::ScatterGather::create(fleet->ctx, cfg, probe, object, std::move(blocks).value());
  if (!sg) return fail("scatter-gather: ", sg.error());
  fleet->client = std::move(sg).value();
  if (!fleet->client->wait_ready(net::Clock::now() + spec.ready_timeout)) {
    std::string who;
    for (const net::WorkerStatus& w : fleet->client->workers())
      if (!w.holds_target) who += (who.empty() ? "" : ", ") + w.endpoint;
    return fail("workers did not load their blocks within ", spec.ready_timeout.count(), " ms: ", who);
  }
  return fleet;
}

}  // namespace st::app
