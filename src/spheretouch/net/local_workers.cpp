// SPDX-License-Identifier: BSD-3-Clause
// LocalWorkers (local_workers.hpp).
#include <spheretouch/net/local_workers.hpp>

#include <future>

namespace st::inline SPHERETOUCH_ABI::net {

std::string inproc_endpoint(int i, const std::string& tag) {
  return "inproc://spheretouch-worker-" + (tag.empty() ? "" : tag + "-") + std::to_string(i);
}

Result<std::unique_ptr<LocalWorkers>> LocalWorkers::start(zmq::context_t& ctx, int n, BackendFactory factory,
                                                          std::function<std::string(int)> endpoint_for, WorkerConfig base) {
  std::unique_ptr<LocalWorkers> w(new LocalWorkers(ctx, std::move(factory), base));
  w->endpoints_.resize(n);
  w->slots_.resize(n);
  for (int i = 0; i < n; ++i)
    if (Status s = w->launch(i, endpoint_for(i)); !s) return Error{s.error()};
  return w;
}

Status LocalWorkers::launch(int i, const std::string& endpoint) {
  Slot& slot = slots_[i];
  slot.stop = std::make_unique<std::atomic<bool>>(false);
  std::promise<Result<std::string>> bound;
  auto fut = bound.get_future();
  WorkerConfig cfg = base_;
  cfg.worker_id = static_cast<std::uint32_t>(i);
  const std::atomic<bool>* stop = slot.stop.get();
  slot.thread = std::thread([this, cfg, endpoint, stop, &bound] {
    Result<std::unique_ptr<WorkerService>> made = WorkerService::create(ctx_, cfg, factory_);
    if (!made) {
      bound.set_value(Error{made.error()});
      return;
    }
    WorkerService& svc = *made.value();
    // A restarted worker's old socket closes its listening fd asynchronously (libzmq's I/O
    // thread): retry the bind briefly instead of failing on EADDRINUSE.
    Status s = svc.bind(endpoint);
    for (int tries = 0; !s && tries < 100; ++tries) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      s = svc.bind(endpoint);
    }
    if (!s) {
      bound.set_value(Error{s.error()});
      return;
    }
    bound.set_value(svc.last_endpoint());
    svc.run(*stop, std::chrono::milliseconds(20));
  });
  Result<std::string> r = fut.get();
  if (!r) {
    slot.thread.join();
    return Error{r.error()};
  }
  endpoints_[i] = r.value();
  return Ok{};
}

void LocalWorkers::stop(int i) {
  Slot& s = slots_[i];
  if (!s.thread.joinable()) return;
  s.stop->store(true);
  s.thread.join();
}

Status LocalWorkers::restart(int i) {
  stop(i);
  return launch(i, endpoints_[i]);
}

LocalWorkers::~LocalWorkers() {
  for (std::size_t i = 0; i < slots_.size(); ++i) stop(static_cast<int>(i));
}

}  // namespace st::net
