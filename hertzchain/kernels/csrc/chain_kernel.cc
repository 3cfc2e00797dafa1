// Fused multi-step kernels for `hertzchain.batched`, a block of chains at a time through all
// the steps of the run while the block's state sits in the cache, every contact's force
// computed once per step and used for both bodies it pushes:
//  - HertzChainForward: the conservative velocity-Verlet step of `batched_step._step` (Hertz
//    contacts, linear sensor springs, static overlaps and external forces of a preload, a
//    wall or a free end), with or without the books (largest overlaps);
//  - HertzChainFullForward / HertzChainFullTangent / HertzChainFullBooks: the full step
//    (velocities and accelerations apart) with Kuwabara-Kono damping and track friction, its
//    forward-mode tangents, and its run with the books (below, `RunFullBlock`); compiled with
//    HC_DASHPOT_LIBRARY (a linear dashpot), HC_POWER_LIBRARY (power-law contacts),
//    HC_THORNTON_LIBRARY or HC_JACKSON_GREEN_LIBRARY (elastic-plastic contacts) into
//    libraries of their own, and with HC_SENSOR_LIBRARY (compliant sensor beads,
//    `hertzchain.compliant_sensor`, forward and tangent runs; alone on Hertz contacts, or
//    beside a law's define on that law) into more.
//
// The arithmetic is that of the JAX kernel, operation for operation and in the same
// order (compiled without contraction into fused multiply-adds), so that the two agree to
// round-off and fits and posteriors keep their numbers (fused multiply-adds in the full
// kernel's drifts and kicks were 9 % faster on an AVX-512 core, but they moved a fit's
// values by 1e-14 and, through the gradients, the NUTS chains' paths: posterior means by
// up to 7e-6 of themselves; not kept); `tests/test_native.py`
// checks it, and `tests/test_batched.py` holds every kernel's laws to `contact`'s. A run's
// blocks of chains are spread over threads (`RunBlocks`). Layouts of the conservative kernel (row-major, the chain on
// the fast axis, as in `batched`):
//   state0, state  (R, B): x (bodies + 1 rows, the wall last, at rest), u = v + (dt/2) a
//                          (bodies + 1), and with books the largest overlap of every
//                          contact so far (bodies rows).
//   inv_mass (bodies + 1, 1 or B), kappa / overlap0 / spring (bodies, 1 or B),
//   external (bodies + 1, 1 or B): a width of 1 is one value shared by every chain.
//   channels (n_channels,): the contacts whose force is recorded after every sample.
//   traces: n_channels results of (B, n_samples), N.
#include <sched.h>
#include <sys/mman.h>
#ifdef __AVX512F__
#include <immintrin.h>
#endif

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstring>
#include <memory>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

#include "xla/ffi/api/ffi.h"

#include "chain_blocks.h"
#include "chain_ffi.h"
#include "chain_laws.h"

// The power-law library's powers and logarithms as glibc's vector functions (libmvec, linked
// by `native` for it): declared SIMD-callable, so that the loops over the lanes that call them
// vectorise (one scalar call per contact and step left them scalar). glibc declares them so
// only under -ffast-math, which the kernels do not use; libmvec's functions are accurate to
// 4 ulp (glibc's manual), the scalar ones to 1.
#if defined(HC_POWER_LIBRARY) && defined(__x86_64__) && defined(__GLIBC__)
extern "C" __attribute__((simd("notinbranch"))) double pow(double, double) noexcept;
extern "C" __attribute__((simd("notinbranch"))) double log(double) noexcept;
#endif

#include "chain_conservative.h"
#include "chain_full_block.h"
#include "chain_lanes.h"
#include "chain_step.h"

namespace ffi = xla::ffi;

// HC_PART (set by `native`'s build): which of the library's handlers this translation unit
// defines. The build compiles the parts in parallel and links them into one library (on 2
// cores about half the wall time of one unit): 1, the conservative kernel and the full
// forward runs; 2, the full kernel's tangent runs and its runs with the books. Undefined: all.
#if !defined(HC_PART) || HC_PART == 1
#define HC_PART_FORWARD 1
#else
#define HC_PART_FORWARD 0
#endif
#if !defined(HC_PART) || HC_PART == 2
#define HC_PART_TANGENT 1
#else
#define HC_PART_TANGENT 0
#endif

// A library of a contact law other than Hertz's (the full kernel's runs only): the law
// (`Law`, chain_full_block.h) that its macro selects (`native.libraries.CONTACT_LAW_DEFINES`):
// the power law (`contact.power_law_force`), Thornton's and Jackson-Green's elastic-plastic
// laws (`contact.thornton_contact`, `contact.jackson_green_contact`).
#if defined(HC_POWER_LIBRARY)
#define HC_LIBRARY_LAW kPower
#elif defined(HC_THORNTON_LIBRARY)
#define HC_LIBRARY_LAW kThornton
#elif defined(HC_JACKSON_GREEN_LIBRARY)
#define HC_LIBRARY_LAW kJacksonGreen
#endif

namespace {

using hertzchain::AsParam;
using hertzchain::Block;
using hertzchain::Directions;
using hertzchain::Load;
using hertzchain::LoadTangent;
using hertzchain::Param;
using hertzchain::RunBlocks;
using hertzchain::Tangent;
using hertzchain::BooksIO;
using hertzchain::ForLanes;
using hertzchain::FullParams;
using hertzchain::IsPlastic;
using hertzchain::kNarrowLanes;
using hertzchain::kQuarterLanes;
using hertzchain::kWideLanes;
using hertzchain::Law;
using hertzchain::LawRows;
using hertzchain::RunBlock;
using hertzchain::SensorRows;
using hertzchain::TangentInputs;


// Asks the kernel to back a large result buffer, written once from end to end, with huge
// pages (a 2 MB page faulted in at once instead of 512 small ones; Linux's transparent huge
// pages in "madvise" mode): the whole 2 MB pages inside [data, data + bytes) only; a hint
// (nothing changes where it is not taken). Only for buffers above the 32 MiB that malloc
// serves from its heaps (`native._keep_freed_buffers`): those are mapped afresh for every
// run, where the page faults of fresh traces cost about a fifth of the arithmetic; smaller
// ones are memory that earlier runs freed, already mapped (advised, they were measured
// less steady).
void AdviseHugePages(void* data, size_t bytes) {
  constexpr uintptr_t kHuge = uintptr_t{1} << 21;
  constexpr size_t kReusedBytes = size_t{32} << 20;
  if (bytes <= kReusedBytes) return;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}


// The full step's run of a block of chains: the loop over its samples and steps that runs the
// step's phases (`chain_step.h`) on the block's state (`chain_full_block.h`).
template <int64_t kLanes, bool kViscous, bool kFriction, bool kTangent, bool kExtras, bool kDashpot, bool kBooks,
          Law kLaw, bool kSensors>
void RunFullBlock(int64_t bodies, int64_t lo, int64_t batch, int64_t n_samples,
                  int64_t steps_per_sample, double dt, const double* state0, FullParams p,
                  const std::vector<int64_t>& channels, const std::vector<double*>& traces,
                  int64_t directions, TangentInputs tin, const std::vector<double*>& ttraces, BooksIO books) {
  using Step = hertzchain::FullStep<kLanes, kViscous, kFriction, kTangent, kExtras, kDashpot, kBooks, kLaw, kSensors>;
  hertzchain::FullBlock<Step> block(bodies, lo, batch, n_samples, steps_per_sample, dt, state0, p, channels, traces,
                                    directions, tin, ttraces, books);
  typename hertzchain::FullBlock<Step>::Lanes lanes = block.StepLanes(dt);  // (never leaves this loop)
  const hertzchain::StepSize size{dt, 0.5 * dt, dt * dt};
  auto out = [&](int64_t set, int64_t c, int64_t j) { return block.out(set, c, j); };
  const int64_t contacts = block.contacts;
  const char *uniform_k = block.uniform_k.data(), *uniform_m = block.uniform_m.data();
  for (int64_t n = 0; n < n_samples; ++n) {
    for (int64_t s = 0; s < steps_per_sample; ++s) {
      block.SensorDrift(size, lanes);
      block.FirstBody(size, lanes);
      for (int64_t i = 0; i < contacts; ++i) {
        if constexpr (IsPlastic(kLaw)) block.GrowPeaks(i, size, lanes);
        // the sweep of the row's uniform kappa (and 1.5 eta kappa) and inverse mass;
        // kOwn: whether the contacts' own inputs have tangents (`fixed_inputs`)
        auto sweep = [&](auto own) HC_LANES {
          constexpr bool kOwn = decltype(own)::value;
          if (uniform_k[i]) {
            uniform_m[i] ? block.template Sweep<true, true, kOwn>(i, size, lanes) : block.template Sweep<true, false, kOwn>(i, size, lanes);
          } else {
            uniform_m[i] ? block.template Sweep<false, true, kOwn>(i, size, lanes)
                               : block.template Sweep<false, false, kOwn>(i, size, lanes);
          }
        };
        if constexpr (kTangent) {
          block.fixed_inputs ? sweep(std::false_type{}) : sweep(std::true_type{});
          block.fixed_inputs ? block.template TangentSweep<true>(i, size, lanes) : block.template TangentSweep<false>(i, size, lanes);
        } else {
          sweep(std::true_type{});
        }
      }
      block.Wall(size, lanes);
      block.SensorKick(size, lanes);
    }
    block.Record(lanes);
    block.record.advance(out);
  }
  if (block.record.buffered) block.record.flush(out);
  if constexpr (kBooks) block.StoreBooks();
}

#if !defined(HC_DASHPOT_LIBRARY) && !defined(HC_LIBRARY_LAW) && !defined(HC_SENSOR_LIBRARY) && \
    HC_PART_FORWARD  // (the main library only)
ffi::Error Forward(ffi::ThreadPool pool, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                   ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0,
                   ffi::Buffer<ffi::F64> spring, ffi::Buffer<ffi::F64> external,
                   ffi::Buffer<ffi::S64> channels, double dt, int64_t steps_per_sample,
                   int64_t preload, int64_t springs, int64_t books,
                   ffi::ResultBuffer<ffi::F64> state, ffi::RemainingRets traces) {
  auto dims = state0.dimensions();
  if (dims.size() != 2) return ffi::Error::InvalidArgument("state0 must be (rows, B)");
  const int64_t batch = dims[1];
  const int64_t bodies = inv_mass.dimensions()[0] - 1;
  const int64_t expected_rows = 2 * (bodies + 1) + (books ? bodies : 0);
  if (dims[0] != expected_rows)
    return ffi::Error::InvalidArgument("state0 rows do not match the bodies and books");
  std::vector<int64_t> rows(channels.typed_data(),
                            channels.typed_data() + channels.element_count());
  std::vector<double*> outs;
  int64_t n_samples = 0;
  for (size_t c = 0; c < rows.size(); ++c) {
    auto out = traces.get<ffi::Buffer<ffi::F64>>(c);
    if (out.has_error()) return out.error();
    auto out_dims = (*out)->dimensions();
    n_samples = out_dims[out_dims.size() - 1];
    outs.push_back((*out)->typed_data());
    AdviseHugePages(outs.back(), (*out)->size_bytes());
    if (rows[c] < 0 || rows[c] >= bodies)
      return ffi::Error::InvalidArgument("a recorded channel is not a contact");
  }
  // blocks of 64 chains, then of 8, the last few chains one at a time
  std::vector<Block> blocks;
  int64_t lo = 0;
  for (; lo + kWideLanes <= batch; lo += kWideLanes) blocks.push_back({lo, kWideLanes});
  for (; lo + kNarrowLanes <= batch; lo += kNarrowLanes) blocks.push_back({lo, kNarrowLanes});
  for (; lo < batch; ++lo) blocks.push_back({lo, 1});
  auto run = [&](auto preload_tag, auto springs_tag, auto books_tag) {
    constexpr bool kP = decltype(preload_tag)::value, kS = decltype(springs_tag)::value,
                   kB = decltype(books_tag)::value;
    auto advance = [&](auto lanes, int64_t first) {
      constexpr int64_t kL = decltype(lanes)::value;
      RunBlock<kL, kP, kS, kB>(bodies, first, batch, n_samples, steps_per_sample, dt,
                               state0.typed_data(), AsParam(inv_mass), AsParam(kappa),
                               AsParam(overlap0), AsParam(spring), AsParam(external), rows,
                               state->typed_data(), outs);
    };
    RunBlocks(pool, blocks, [&](int64_t b) {
      const Block& block = blocks[b];
      if (block.lanes == kWideLanes) return advance(std::integral_constant<int64_t, kWideLanes>{}, block.lo);
      if (block.lanes == kNarrowLanes) return advance(std::integral_constant<int64_t, kNarrowLanes>{}, block.lo);
      advance(std::integral_constant<int64_t, 1>{}, block.lo);
    });
  };
  using T = std::true_type;
  using F = std::false_type;
  auto with_books = [&](auto p, auto s) { books ? run(p, s, T{}) : run(p, s, F{}); };
  auto with_springs = [&](auto p) { springs ? with_books(p, T{}) : with_books(p, F{}); };
  preload ? with_springs(T{}) : with_springs(F{});
  return ffi::Error::Success();
}
#endif  // HC_DASHPOT_LIBRARY


// What a run of the full kernel computes: the recorded forces (kForward), with their
// tangents (kTangent, `tangents` given), or with the books (kBooks, `books` given).
enum class Pass { kForward, kTangent, kBooks };

// The law of this library's runs: its law macro's (HC_LIBRARY_LAW, above), else Hertz's.
#if defined(HC_LIBRARY_LAW)
constexpr Law kLibraryLaw = Law::HC_LIBRARY_LAW;
#else
constexpr Law kLibraryLaw = Law::kHertz;
#endif
// The libraries of a law other than Hertz's: their laws' scalar calls (powers, exponentials)
// leave the loops over the lanes unvectorised, so they run blocks of 8 only (blocks of 64, 8
// and 4 ran the power law no faster and built in 20 s, not 11 s).
constexpr bool kLawLibrary = kLibraryLaw != Law::kHertz;
// The compliant sensors' libraries (HC_SENSOR_LIBRARY: Hertz contacts, or with a law's define
// that law's, with or without a dashpot, forward and tangent runs): their runs carry the
// sensors (`RunFullBlock`'s kSensors), the others refuse them.
#if defined(HC_SENSOR_LIBRARY)
constexpr bool kSensorLibrary = true;
#else
constexpr bool kSensorLibrary = false;
#endif
// Libraries that run blocks of one width only (a partial last block repeats its last chain):
// the laws other than Hertz's blocks of 8, the sensors' blocks of 4, one AVX2 vector (a
// diagnosis evaluates 4-10 traces: an AVX-512 core that splits 512-bit operations in two
// ran 4 chains in an 8-lane block in twice the time; with blocks of 8, 4 and 1 the library
// built in 34 s, with blocks of 8 or of 4 alone in 14 s, on 2 cores).
constexpr bool kOneWidth = kLawLibrary || kSensorLibrary;
constexpr int64_t kOneWidthLanes = kSensorLibrary ? kQuarterLanes : kNarrowLanes;

// state0 and parameters as for the full kernel.
template <Pass kPass>
ffi::Error RunFull(ffi::ThreadPool& pool, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                   ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0,
                   ffi::Buffer<ffi::F64> spring, ffi::Buffer<ffi::F64> external,
                   ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction, ffi::Buffer<ffi::F64> dashpot,
                   ffi::Buffer<ffi::F64> law, ffi::Buffer<ffi::F64> sensors, ffi::Buffer<ffi::S64> channels,
                   ffi::Buffer<ffi::S64> beads, double dt, int64_t steps_per_sample,
                   int64_t viscous, int64_t friction_on, int64_t extras, int64_t dashpot_on,
                   const TangentInputs* tangents, ffi::RemainingRets results, const BooksIO* books = nullptr) {
  auto dims = state0.dimensions();
  const int64_t batch = dims[dims.size() - 1];
  const int64_t bodies = inv_mass.dimensions()[inv_mass.dimensions().size() - 2] - 1;
  const int64_t n_sensors = static_cast<int64_t>(beads.element_count());
  if (n_sensors > 0 && !kSensorLibrary)
    return ffi::Error::InvalidArgument("compliant sensors run the sensor library's kernel (HC_SENSOR_LIBRARY)");
  if (n_sensors > 0 && books) return ffi::Error::InvalidArgument("compliant sensors: the kernel keeps no books");
  const int64_t peak_rows = books && IsPlastic(kLibraryLaw) ? bodies : 0;
  const int64_t state_rows = 3 * (bodies + 1) + 3 * n_sensors +
                             (books ? peak_rows + bodies + (viscous ? bodies + 1 : 0) + 1 : 0);
  if (static_cast<int64_t>(state0.element_count()) != state_rows * batch)
    return ffi::Error::InvalidArgument(books ? "state0 must be (3 (bodies + 1) + the books' rows, B)"
                                             : "state0 must be (3 (bodies + 1) + 3 sensors, B) for one primal");
  const int64_t* bead = beads.typed_data();
  std::vector<char> seen(2 * bodies, 0);  // each contact the back of one sensor and the front of one at most
  for (int64_t k = 0; k < n_sensors; ++k) {
    if (bead[k] < 1 || bead[k] >= bodies)
      return ffi::Error::InvalidArgument("a sensor bead K needs contacts K - 1 and K in the chain");
    if (seen[bead[k] - 1] || seen[bodies + bead[k]])
      return ffi::Error::InvalidArgument("a sensor bead is listed twice");
    seen[bead[k] - 1] = seen[bodies + bead[k]] = 1;
  }
  if (static_cast<int64_t>(sensors.element_count()) != SensorRows(n_sensors) &&
      static_cast<int64_t>(sensors.element_count()) != SensorRows(n_sensors) * batch)
    return ffi::Error::InvalidArgument("sensors must be (4 sensors + 1, 1 or B) (chain_kernel.cc, SensorRows)");
  std::vector<int64_t> rows(channels.typed_data(),
                            channels.typed_data() + channels.element_count());
  // results: one (B, n_samples) trace per channel, then (tangents) one (D, B, n_samples)
  std::vector<double*> outs, touts;
  int64_t n_samples = 0, directions = 0;
  const size_t n_channels = rows.size();
  for (size_t c = 0; c < (tangents ? 2 : 1) * n_channels; ++c) {
    auto out = results.get<ffi::Buffer<ffi::F64>>(c);
    if (out.has_error()) return out.error();
    auto out_dims = (*out)->dimensions();
    n_samples = out_dims[out_dims.size() - 1];
    if (c < n_channels) {
      outs.push_back((*out)->typed_data());
      AdviseHugePages(outs.back(), (*out)->size_bytes());
      if (rows[c] < 0 || rows[c] >= bodies)
        return ffi::Error::InvalidArgument("a recorded channel is not a contact");
    } else {
      directions = static_cast<int64_t>((*out)->element_count()) / (batch * n_samples);
      touts.push_back((*out)->typed_data());
      AdviseHugePages(touts.back(), (*out)->size_bytes());
    }
  }
  const int64_t law_rows = LawRows(kLibraryLaw, bodies);
  if (static_cast<int64_t>(law.element_count()) != law_rows &&
      static_cast<int64_t>(law.element_count()) != law_rows * batch)
    return ffi::Error::InvalidArgument("law must be (rows, 1 or B): the law's parameters (chain_kernel.cc, LawRows)");
  FullParams p{AsParam(inv_mass), AsParam(kappa),    AsParam(overlap0), AsParam(spring), AsParam(external),
               AsParam(eta),      AsParam(friction), AsParam(dashpot),  AsParam(law),    AsParam(sensors),
               bead,              n_sensors};
  TangentInputs none{};
  const TangentInputs& tin = tangents ? *tangents : none;
  const BooksIO no_books{};
  const BooksIO& kept = books ? *books : no_books;
  // blocks of 64, then of 8 (the last one may be partial), the last 2-4 chains in a block
  // of 4 (a vector costs about what one chain alone does), a last single chain alone; runs
  // with the books (sweeps: large batches) in blocks of 64 and 8 only, so that they add two
  // block widths to the library's build, not four; tangent runs in blocks of 8, 4 and 1, not
  // 64: the Jacobian of 128 or 1024 chains in 5 directions took the same time in blocks of 8
  // (medians 1.08 and 1.05 of the 64-wide blocks', 0.97 in a rerun of 1024 chains: within the
  // spread of repeats), and the 64-wide tangent instantiations were 12 of the 42 s of compiling
  // the main library's tangent part, 10 of 29 s for the dashpot's
  // (benchmarks/results/tangent_block_width/); the laws other than Hertz's and the compliant
  // sensors in blocks of one width (`kOneWidth`)
  std::vector<Block> blocks;
  int64_t lo = 0;
  if constexpr (kOneWidth)
    for (; lo < batch; lo += kOneWidthLanes) blocks.push_back({lo, kOneWidthLanes});
  constexpr bool kB = kPass == Pass::kBooks;
  if constexpr (kPass != Pass::kTangent)
    for (; lo + kWideLanes <= batch; lo += kWideLanes) blocks.push_back({lo, kWideLanes});
  int64_t narrow = 0;
  for (; batch - lo > (kB ? 0 : kQuarterLanes); lo += kNarrowLanes, ++narrow)
    blocks.push_back({lo, kNarrowLanes});
  // an odd number of 8-lane blocks and nothing after them leaves a thread idle while another
  // runs the last one: its chains go as two blocks of 4, one per thread (a fit iteration of
  // 8 traces on 2 cores of an AVX-512 Xeon 24.7 -> 16.5 ms, 24 traces 50.5 -> 40.3 ms:
  // benchmarks/results/fit_iteration_scaling/)
  // (two threads: the caller and a helper of the pool, on two CPUs at least)
  if (!kB && narrow % 2 == 1 && lo >= batch && pool.num_threads() >= 1 &&
      hertzchain::CpuLimit() >= 2) {
    const int64_t last = blocks.back().lo;
    blocks.back() = {last, kQuarterLanes};
    blocks.push_back({last + kQuarterLanes, kQuarterLanes});
  }
  if (batch - lo >= 2) {
    blocks.push_back({lo, kQuarterLanes});
    lo += kQuarterLanes;
  }
  if (lo < batch) blocks.push_back({lo, 1});
  auto run = [&](auto viscous_tag, auto friction_tag, auto extras_tag, auto dashpot_tag) {
    constexpr bool kV = decltype(viscous_tag)::value, kF = decltype(friction_tag)::value,
                   kT = kPass == Pass::kTangent, kE = decltype(extras_tag)::value,
                   kD = decltype(dashpot_tag)::value;
    auto advance = [&](auto lanes, int64_t first) {
      constexpr int64_t kL = decltype(lanes)::value;
      // blocks of 8 and 4 with the extras' terms (zeros: the same numbers): without them
      // GCC 12 leaves the damped 8-lane loop scalar ("control flow in loop"), 2.5x slower
      constexpr bool kENarrow = kE || kL == kNarrowLanes || kL == kQuarterLanes;
      RunFullBlock<kL, kV, kF, kT, kENarrow, kD, kB, kLibraryLaw, kSensorLibrary>(
          bodies, first, batch, n_samples, steps_per_sample, dt, state0.typed_data(), p, rows, outs, directions, tin,
          touts, kept);
    };
    RunBlocks(pool, blocks, [&](int64_t b) {
      const Block& block = blocks[b];
      if constexpr (kOneWidth) {
        advance(std::integral_constant<int64_t, kOneWidthLanes>{}, block.lo);
      } else {
        if constexpr (kPass != Pass::kTangent)
          if (block.lanes == kWideLanes) return advance(std::integral_constant<int64_t, kWideLanes>{}, block.lo);
        if (block.lanes == kNarrowLanes) return advance(std::integral_constant<int64_t, kNarrowLanes>{}, block.lo);
        if constexpr (!kB) {
          if (block.lanes == kQuarterLanes) return advance(std::integral_constant<int64_t, kQuarterLanes>{}, block.lo);
          advance(std::integral_constant<int64_t, 1>{}, block.lo);
        }
      }
    });
  };
  using T = std::true_type;
  using F = std::false_type;
  // the tangents and the books always with the preload's and springs' terms (zeros where
  // there are none); a dashpot (damped runs only: the kernels compute rates with the
  // damping) likewise, so that its few runs add four instantiations per block width, not eight
  auto with_extras = [&](auto v, auto f, auto d) {
    if constexpr (kPass != Pass::kForward || decltype(d)::value) {
      run(v, f, T{}, d);
    } else {
      extras ? run(v, f, T{}, d) : run(v, f, F{}, d);
    }
  };
  auto with_friction = [&](auto v, auto d) { friction_on ? with_extras(v, T{}, d) : with_extras(v, F{}, d); };
  // The dashpot's runs and the other laws' are compiled into libraries of their own
  // (HC_DASHPOT_LIBRARY, HC_POWER_LIBRARY, HC_THORNTON_LIBRARY, HC_JACKSON_GREEN_LIBRARY, built
  // on first use by `native`), so that the library every run needs does not wait for them;
  // a law's library runs its law with and without a dashpot, and so do the compliant
  // sensors' libraries (HC_SENSOR_LIBRARY, on Hertz's law or on a law's define).
#if defined(HC_LIBRARY_LAW) || defined(HC_SENSOR_LIBRARY)
  if (dashpot_on && !viscous)
    return ffi::Error::InvalidArgument("a dashpot runs with damping only (the kernels compute rates with it)");
  if (dashpot_on) {
    with_friction(T{}, T{});
  } else {
    viscous ? with_friction(T{}, F{}) : with_friction(F{}, F{});
  }
#elif defined(HC_DASHPOT_LIBRARY)
  if (!dashpot_on || !viscous)
    return ffi::Error::InvalidArgument("the dashpot library runs damped chains with a dashpot only");
  with_friction(T{}, T{});
#else
  if (dashpot_on) return ffi::Error::InvalidArgument("a dashpot runs the dashpot library's kernel");
  viscous ? with_friction(T{}, F{}) : with_friction(F{}, F{});
#endif
  return ffi::Error::Success();
}

#if HC_PART_FORWARD
ffi::Error FullForward(ffi::ThreadPool pool, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                       ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0,
                       ffi::Buffer<ffi::F64> spring, ffi::Buffer<ffi::F64> external,
                       ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction, ffi::Buffer<ffi::F64> dashpot,
                       ffi::Buffer<ffi::F64> law, ffi::Buffer<ffi::F64> sensors, ffi::Buffer<ffi::S64> channels,
                       ffi::Buffer<ffi::S64> beads, double dt, int64_t steps_per_sample, int64_t viscous,
                       int64_t friction_on, int64_t extras, int64_t dashpot_on, ffi::RemainingRets traces) {
  return RunFull<Pass::kForward>(pool, state0, inv_mass, kappa, overlap0, spring, external, eta, friction, dashpot,
                                 law, sensors, channels, beads, dt, steps_per_sample, viscous, friction_on, extras,
                                 dashpot_on, nullptr, traces);
}
#endif  // HC_PART_FORWARD

#if HC_PART_TANGENT && !defined(HC_SENSOR_LIBRARY)
// The full forward run with the books (`BooksIO`): state0 and the result `state` the packed
// state of `batched._Layout` (x, v, a, the largest forces, with damping the viscous forces,
// the dissipated energy), `mass` (bodies, 1 or B), kg.
ffi::Error FullBooks(ffi::ThreadPool pool, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                     ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0,
                     ffi::Buffer<ffi::F64> spring, ffi::Buffer<ffi::F64> external,
                     ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction, ffi::Buffer<ffi::F64> dashpot,
                     ffi::Buffer<ffi::F64> law, ffi::Buffer<ffi::F64> sensors, ffi::Buffer<ffi::F64> mass,
                     ffi::Buffer<ffi::S64> channels, ffi::Buffer<ffi::S64> beads, double dt, int64_t steps_per_sample,
                     int64_t viscous, int64_t friction_on, int64_t extras, int64_t dashpot_on,
                     ffi::ResultBuffer<ffi::F64> state, ffi::RemainingRets traces) {
  if (state->element_count() != state0.element_count())
    return ffi::Error::InvalidArgument("the books' state must have state0's shape");
  const BooksIO books{state0.typed_data(), AsParam(mass), state->typed_data()};
  return RunFull<Pass::kBooks>(pool, state0, inv_mass, kappa, overlap0, spring, external, eta, friction, dashpot,
                               law, sensors, channels, beads, dt, steps_per_sample, viscous, friction_on, extras,
                               dashpot_on, nullptr, traces, &books);
}
#endif  // HC_PART_TANGENT && !HC_SENSOR_LIBRARY

#if HC_PART_TANGENT

ffi::Error FullTangent(ffi::ThreadPool pool, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                       ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0,
                       ffi::Buffer<ffi::F64> spring, ffi::Buffer<ffi::F64> external,
                       ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction, ffi::Buffer<ffi::F64> dashpot,
                       ffi::Buffer<ffi::F64> law, ffi::Buffer<ffi::F64> sensors, ffi::Buffer<ffi::F64> t_state0, ffi::Buffer<ffi::F64> t_inv_mass,
                       ffi::Buffer<ffi::F64> t_kappa, ffi::Buffer<ffi::F64> t_overlap0,
                       ffi::Buffer<ffi::F64> t_spring, ffi::Buffer<ffi::F64> t_external,
                       ffi::Buffer<ffi::F64> t_eta, ffi::Buffer<ffi::F64> t_friction,
                       ffi::Buffer<ffi::F64> t_dashpot, ffi::Buffer<ffi::F64> t_law, ffi::Buffer<ffi::F64> t_sensors,
                       ffi::Buffer<ffi::S64> channels, ffi::Buffer<ffi::S64> beads, double dt,
                       int64_t steps_per_sample, int64_t viscous, int64_t friction_on, int64_t extras,
                       int64_t dashpot_on, ffi::RemainingRets tangent_traces) {
  auto dims = state0.dimensions();
  const int64_t batch = dims[dims.size() - 1];
  const int64_t rows_x = inv_mass.dimensions()[inv_mass.dimensions().size() - 2];
  const int64_t n_sensors = static_cast<int64_t>(beads.element_count());
  const int64_t counts[11] = {
      Directions(t_state0, 3 * rows_x + 3 * n_sensors, batch), Directions(t_inv_mass, rows_x, batch),
      Directions(t_kappa, rows_x - 1, batch),  Directions(t_overlap0, rows_x - 1, batch),
      Directions(t_spring, rows_x - 1, batch), Directions(t_external, rows_x, batch),
      Directions(t_eta, 1, batch),             Directions(t_friction, 1, batch),
      Directions(t_dashpot, 1, batch),         Directions(t_law, LawRows(kLibraryLaw, rows_x - 1), batch),
      Directions(t_sensors, SensorRows(n_sensors), batch)};
  const int64_t directions = *std::max_element(counts, counts + 11);
  for (int64_t count : counts)
    if (count != 1 && count != directions)
      return ffi::Error::InvalidArgument("tangents must be (directions or 1, rows, B)");
  auto tangent = [&](const ffi::Buffer<ffi::F64>& buffer, int64_t count) {
    return Tangent{buffer.typed_data(), count == 1};
  };
  TangentInputs tin{tangent(t_state0, counts[0]),    tangent(t_inv_mass, counts[1]),
                    tangent(t_kappa, counts[2]),     tangent(t_overlap0, counts[3]),
                    tangent(t_spring, counts[4]),    tangent(t_external, counts[5]),
                    tangent(t_eta, counts[6]),       tangent(t_friction, counts[7]),
                    tangent(t_dashpot, counts[8]),    tangent(t_law, counts[9]),
                    tangent(t_sensors, counts[10])};
  return RunFull<Pass::kTangent>(pool, state0, inv_mass, kappa, overlap0, spring, external, eta, friction, dashpot,
                                 law, sensors, channels, beads, dt, steps_per_sample, viscous, friction_on, extras,
                                 dashpot_on, &tin, tangent_traces);
}
#endif  // HC_PART_TANGENT

}  // namespace

// The handlers' argument lists: `chain_ffi.h` (the recorded channels, a buffer here, after
// the parameters); the host's full kernels also take the contact law's parameters (`law`,
// `LawRows`: read by the law libraries, zeros elsewhere) and the compliant sensors' (`sensors`,
// `SensorRows`: read by the sensor library) after the full kernels' arguments, and the
// sensors' beads (a buffer, empty without) after the channels.
template <class Binding>
auto HostFullArgs(Binding&& binding) {
  return hertzchain::FullArgs(std::forward<Binding>(binding))
      .template Arg<ffi::Buffer<ffi::F64>>()   // law
      .template Arg<ffi::Buffer<ffi::F64>>();  // sensors
}

#if !defined(HC_DASHPOT_LIBRARY) && !defined(HC_LIBRARY_LAW) && !defined(HC_SENSOR_LIBRARY) && HC_PART_FORWARD
XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainForward, Forward,
                              hertzchain::ForwardAttrs(hertzchain::ChainArgs(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>())
                                                           .Arg<ffi::Buffer<ffi::S64>>())  // channels
                                  .Ret<ffi::Buffer<ffi::F64>>()  // state
                                  .RemainingRets());             // traces
#endif

#if HC_PART_FORWARD
XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainFullForward, FullForward,
                              hertzchain::FullAttrs(HostFullArgs(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>())
                                                        .Arg<ffi::Buffer<ffi::S64>>()   // channels
                                                        .Arg<ffi::Buffer<ffi::S64>>())  // sensor beads
                                  .RemainingRets());                                    // traces
#endif

#if HC_PART_TANGENT && !defined(HC_SENSOR_LIBRARY)
XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainFullBooks, FullBooks,
                              hertzchain::FullAttrs(HostFullArgs(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>())
                                                        .Arg<ffi::Buffer<ffi::F64>>()   // mass
                                                        .Arg<ffi::Buffer<ffi::S64>>()   // channels
                                                        .Arg<ffi::Buffer<ffi::S64>>())  // sensor beads
                                  .Ret<ffi::Buffer<ffi::F64>>()  // state
                                  .RemainingRets());             // traces
#endif

#if HC_PART_TANGENT

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    HertzChainFullTangent, FullTangent,
    hertzchain::FullAttrs(
        HostFullArgs(HostFullArgs(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>()))  // values, tangents
            .Arg<ffi::Buffer<ffi::S64>>()                                    // channels
            .Arg<ffi::Buffer<ffi::S64>>())                                   // sensor beads
        .RemainingRets());  // traces, then their tangents
#endif  // HC_PART_TANGENT
