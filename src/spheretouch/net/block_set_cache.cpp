// SPDX-License-Identifier: BSD-3-Clause
// BlockSetCache (block_set_cache.hpp).
#include <spheretouch/net/block_set_cache.hpp>

#include <malloc.h>

#include <chrono>

#include <spheretouch/geom/check.hpp>

namespace st::inline SPHERETOUCH_ABI::net::client {

Result<SetPtr> encode_set(const SceneData& s, std::vector<std::uint32_t> blocks) {
  auto bs = make_block_set(s.probe, s.object, s.blocks, blocks, s.leaf_faces, s.object_id);
  if (!bs) return Error{bs.error()};
  auto e = std::make_shared<EncodedSet>();
  e->blocks = std::move(blocks);
  e->bytes = encode_block_set(bs.value());
  e->hash = block_set_hash(e->bytes);
  return SetPtr(std::move(e));
}

class BlockSetCache::Encoder {
 public:
  Encoder() : thread_([this] { loop(); }) {}
  Encoder(const Encoder&) = delete;
  Encoder& operator=(const Encoder&) = delete;
  ~Encoder() {
    {
      std::lock_guard<std::mutex> g(m_);
      stop_ = true;  // pending jobs are dropped: their futures report a broken promise
    }
    cv_.notify_one();
    thread_.join();
  }
  std::future<Result<SetPtr>> submit(std::function<Result<SetPtr>()> job) {
    std::packaged_task<Result<SetPtr>()> task(std::move(job));
    auto done = task.get_future();
    {
      std::lock_guard<std::mutex> g(m_);
      jobs_.push_back(std::move(task));
    }
    cv_.notify_one();
    return done;
  }

 private:
  void loop() {
    for (;;) {
      std::packaged_task<Result<SetPtr>()> task;
      {
        std::unique_lock<std::mutex> l(m_);
        cv_.wait(l, [this] { return stop_ || !jobs_.empty(); });
        if (stop_) return;
        task = std::move(jobs_.front());
        jobs_.pop_front();
      }
      task();
    }
  }
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<std::packaged_task<Result<SetPtr>()>> jobs_;
  bool stop_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

BlockSetCache::BlockSetCache(std::shared_ptr<const SceneData> scene)
    : scene_(std::move(scene)), encoder_(std::make_unique<Encoder>()) {}

BlockSetCache::~BlockSetCache() = default;

void BlockSetCache::remember(const SetPtr& s) {
  by_blocks_[s->blocks] = s;
  by_hash_[s->hash] = s;
}

SetPtr BlockSetCache::get(const std::vector<std::uint32_t>& blocks) {
  if (auto it = by_blocks_.find(blocks); it != by_blocks_.end()) return it->second;
  auto f = encoding_.find(blocks);
  if (f == encoding_.end()) {
    // Encoding a multi-megabyte share takes milliseconds: never inside a round's deadline.
    encoding_.emplace(blocks, encoder_->submit([s = scene_, blocks] { return encode_set(*s, blocks); }));
    return nullptr;
  }
  if (f->second.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return nullptr;
  Result<SetPtr> r = f->second.get();
  encoding_.erase(f);
  ST_ASSERT(r.ok(), "blocks come from our own partition, so they encode");
  if (!r) return nullptr;
  remember(r.value());
  return r.value();
}

SetPtr BlockSetCache::find(std::uint64_t hash) const {
  const auto it = by_hash_.find(hash);
  return it == by_hash_.end() ? nullptr : it->second;
}

std::size_t BlockSetCache::prune(const std::function<bool(const EncodedSet&)>& keep) {
  for (auto it = encoding_.begin(); it != encoding_.end();) {
    if (it->second.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
      ++it;
      continue;
    }
    if (Result<SetPtr> r = it->second.get(); r) remember(r.value());
    it = encoding_.erase(it);
  }
  std::size_t dropped = 0;
  for (auto it = by_blocks_.begin(); it != by_blocks_.end();) {
    if (keep(*it->second)) {
      ++it;
      continue;
    }
    by_hash_.erase(it->second->hash);
    it = by_blocks_.erase(it);
    ++dropped;
  }
  if (dropped) ::malloc_trim(0);  // encoded sets are megabytes: give them back to the system
  return dropped;
}

}  // namespace st::net::client
