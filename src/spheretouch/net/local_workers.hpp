// SPDX-License-Identifier: BSD-3-Clause
/// \file
/// LocalWorkers: N WorkerServices on threads of this process — the embedded default (inproc://),
/// and the benchmark's workers over ipc:// or tcp:// loopback. Each worker can be stopped and
/// started again (a fresh epoch, empty memory), as a crashed and restarted daemon would be.
#pragma once
#include <spheretouch/abi.hpp>
#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include <spheretouch/net/worker_service.hpp>

namespace st::inline SPHERETOUCH_ABI::net {

/// Workers on threads, stopped and joined on destruction.
class LocalWorkers {
 public:
  /// Starts `n` workers in `ctx`; worker i binds endpoint_for(i) (a tcp wildcard port is resolved)
  /// and gets worker_id i. Fails, naming the endpoint, if a bind fails.
  static Result<std::unique_ptr<LocalWorkers>> start(zmq::context_t& ctx, int n, BackendFactory factory,
                                                     std::function<std::string(int)> endpoint_for, WorkerConfig base = {});
  ~LocalWorkers();
  LocalWorkers(const LocalWorkers&) = delete;
  LocalWorkers& operator=(const LocalWorkers&) = delete;

  const std::vector<std::string>& endpoints() const { return endpoints_; }  ///< resolved, by worker
  void stop(int i);       ///< stops worker i (its socket closes; memory is lost)
  Status restart(int i);  ///< starts worker i again on the same endpoint, with a new epoch

 private:
  struct Slot {
    std::unique_ptr<std::atomic<bool>> stop;
    std::thread thread;
  };
  LocalWorkers(zmq::context_t& ctx, BackendFactory f, WorkerConfig base)
      : ctx_(ctx), factory_(std::move(f)), base_(base) {}
  Status launch(int i, const std::string& endpoint);

  zmq::context_t& ctx_;
  BackendFactory factory_;
  WorkerConfig base_;
  std::vector<std::string> endpoints_;
  std::vector<Slot> slots_;
};

/// "inproc://spheretouch-worker-<i>" (unique per process when `tag` differs).
std::string inproc_endpoint(int i, const std::string& tag = "");

}  // namespace st::net
