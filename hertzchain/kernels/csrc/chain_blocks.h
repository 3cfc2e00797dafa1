// What the host kernels (`chain_kernel.cc`, `driven_kernel.cc`) share: their parameters'
// and tangents' layouts, and the threads that run a call's blocks of chains (or runs).
#pragma once

#include <sched.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "xla/ffi/api/ffi.h"

namespace hertzchain {

namespace ffi = xla::ffi;

struct Param {
  const double* data;
  int64_t width;  // 1 (shared by the batch) or B
};

// Rows of `p` for chains lo..lo+kLanes-1 into a (rows, kLanes) block; lanes from `valid`
// on (a block past the end of the batch) repeat the last valid chain.
template <int64_t kLanes>
void Load(Param p, int64_t rows, int64_t lo, double* block, int64_t valid = kLanes) {
  for (int64_t r = 0; r < rows; ++r)
    for (int64_t j = 0; j < kLanes; ++j)
      block[r * kLanes + j] = p.width == 1 ? p.data[r] : p.data[r * p.width + lo + std::min(j, valid - 1)];
}

// ---------------------------------------------------------------------------------------
// Threads. A run's blocks of chains are independent: the calling thread and helpers on
// XLA's intra-op thread pool take them one at a time (the first free thread the next block,
// as a `prange` does), each block's numbers the same whichever thread runs it. All the runs
// of the process together use at most as many threads as it may use CPUs: a batch split
// over host devices (a thread per device already) gets no helpers while both run, and a
// helper leaves as soon as another run starts.

struct Block {
  int64_t lo, lanes;
};

inline int CpuLimit() {
  cpu_set_t set;
  if (sched_getaffinity(0, sizeof(set), &set) == 0) return std::max(1, CPU_COUNT(&set));
  return std::max(1u, std::thread::hardware_concurrency());
}

inline std::atomic<int> active_threads{0};  // threads running blocks, every run of the process

// The state a run shares with its helpers; a helper that starts after the last block was
// taken only reads it (kept alive by its shared_ptr), never the run's buffers.
struct BlockQueue {
  explicit BlockQueue(int64_t n) : n_blocks(n) {}
  const int64_t n_blocks;
  std::atomic<int64_t> next{0};
  int64_t finished = 0;  // guarded by `mutex`
  std::mutex mutex;
  std::condition_variable all_done;
};

// Takes blocks until none is left; `run(b)` runs block b. A helper (`limit` > 0) also stops
// before its next block when more threads than `limit` run blocks: another run of the
// process (another host device's) has started since, and the two must not share a CPU (a
// run waits for its last block, and a helper sharing a CPU finishes it late). Helpers that
// stayed put a batch split over two host devices at 0.73x the Numba baseline's speed
// (damped), 0.96x once they leave (`benchmarks/README.md`).
template <class Run>
void TakeBlocks(BlockQueue& queue, const Run& run, int limit = 0) {
  while (limit == 0 || active_threads.load() <= limit) {
    const int64_t b = queue.next.fetch_add(1);
    if (b >= queue.n_blocks) return;
    run(b);
    std::lock_guard<std::mutex> lock(queue.mutex);
    if (++queue.finished == queue.n_blocks) queue.all_done.notify_all();
  }
}

template <class Run>
void RunBlocks(ffi::ThreadPool& pool, const std::vector<Block>& blocks, const Run& run) {
  auto queue = std::make_shared<BlockQueue>(static_cast<int64_t>(blocks.size()));
  const int limit = CpuLimit();
  const int64_t helpers = std::min<int64_t>({pool.num_threads(), limit - 1, queue->n_blocks - 1});
  active_threads.fetch_add(1);
  for (int64_t t = 0; t < helpers; ++t)
    pool.Schedule([queue, &run, limit]() {
      if (queue->next.load() >= queue->n_blocks) return;  // nothing left: `run` may be gone
      if (active_threads.fetch_add(1) >= limit) {           // every CPU busy already
        active_threads.fetch_sub(1);
        return;
      }
      TakeBlocks(*queue, run, limit);
      active_threads.fetch_sub(1);
    });
  TakeBlocks(*queue, run);
  active_threads.fetch_sub(1);
  std::unique_lock<std::mutex> lock(queue->mutex);
  queue->all_done.wait(lock, [&] { return queue->finished == queue->n_blocks; });
}

inline Param AsParam(const ffi::Buffer<ffi::F64>& buffer) {
  auto dims = buffer.dimensions();
  return {buffer.typed_data(), dims.size() > 1 ? dims[dims.size() - 1] : 1};
}

// The leading size of a tangent input: its element count over rows x B.
inline int64_t Directions(const ffi::Buffer<ffi::F64>& buffer, int64_t rows, int64_t batch) {
  return static_cast<int64_t>(buffer.element_count()) / (rows * batch);
}

// A tangent input: (D, rows, B), or (1, rows, B) for one tangent shared by every direction
// (an input that does not vary along a jacfwd's basis).
struct Tangent {
  const double* data;
  bool shared;
};

// Rows of every tangent direction of chains lo.. into (D, rows, kLanes).
template <int64_t kLanes>
void LoadTangent(Tangent t, int64_t directions, int64_t rows, int64_t batch, int64_t lo,
                 double* block, int64_t valid) {
  for (int64_t d = 0; d < directions; ++d) {
    const double* src = t.data + (t.shared ? 0 : d * rows * batch);
    for (int64_t r = 0; r < rows; ++r)
      for (int64_t j = 0; j < kLanes; ++j)
        block[(d * rows + r) * kLanes + j] = src[r * batch + lo + std::min(j, valid - 1)];
  }
}

}  // namespace hertzchain
