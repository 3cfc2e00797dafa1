// Fused multi-step kernels for `hertzchain.batched`, a block of chains at a time through all
// the steps of the run while the block's state sits in the cache, every contact's force
// computed once per step and used for both bodies it pushes:
//  - HertzChainForward: the conservative velocity-Verlet step of `batched._step` (Hertz
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

// A library of a contact law other than Hertz's (the full kernel's runs only).
#if defined(HC_POWER_LIBRARY) || defined(HC_THORNTON_LIBRARY) || defined(HC_JACKSON_GREEN_LIBRARY)
#define HC_LAW_LIBRARY 1
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

// Chains advanced together (the vectorised axis): blocks of 64 (measured best on a 2-core
// AVX-512 EPYC against 16, 32 and 128: the block's state stays in L1/L2), the remainder of
// the batch in blocks of 8 (one AVX-512 vector) and the last few chains one at a time (a
// single chain in an 8-lane block ran at half the speed of the JAX kernel).
// The lane loops carry `#pragma GCC unroll 8` (a 64-lane block is eight AVX-512 vectors,
// sixteen AVX2 ones): GCC 12 left the full kernel's sweep rolled, one vector at a time,
// which cost it 30 % (one core: 5.4e8 against 7.7e8 bead-steps/s, N = 21, eta and mu on).
constexpr int64_t kWideLanes = 64;
constexpr int64_t kNarrowLanes = 8;
// The full kernel's last 2-4 chains: one AVX2 vector (an AVX-512 core that splits 512-bit
// operations in two runs it in half the time of a partial 8-lane block).
constexpr int64_t kQuarterLanes = 4;
// `body(j)` for every lane j of a block of kLanes chains, vectorised (the lanes are
// independent), and for a 64-lane block unrolled in full (see above); narrower blocks are
// one or a few vectors already (unrolled before vectorisation, the tangent run of an
// 8-lane block was 4x slower). The loop and its bodies (`HC_LANES`) are always inlined: the
// tangent sweep's body, with its contact law on dual numbers, is larger than GCC 12 inlines
// on its own, and a loop that calls it per lane stays scalar (3.5x the instructions).
#define HC_LANES __attribute__((always_inline))
template <int64_t kLanes, class Body>
HC_LANES inline void ForLanes(const Body& body) {
  if constexpr (kLanes == 64) {
#pragma GCC ivdep
#pragma GCC unroll 8
    for (int64_t j = 0; j < kLanes; ++j) body(j);
  } else {
#pragma GCC ivdep
    for (int64_t j = 0; j < kLanes; ++j) body(j);
  }
}
constexpr int64_t kSampleBuffer = 8;    // samples kept per chain before they are written out (a cache line)

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


// Whether every lane of row r of a (rows, kLanes) block holds the same bits: the row is
// then read as one broadcast value (the same numbers, one load less per lane and step, and
// a block small enough for L1).
template <int64_t kLanes>
std::vector<char> UniformRows(const double* block, int64_t rows) {
  std::vector<char> uniform(rows);
  for (int64_t r = 0; r < rows; ++r) {
    bool same = true;
    for (int64_t j = 1; j < kLanes; ++j)
      same = same && std::memcmp(&block[r * kLanes + j], &block[r * kLanes], sizeof(double)) == 0;
    uniform[r] = same;
  }
  return uniform;
}

#ifdef __AVX512F__
// Rows in[s * stride + 0..7], s = 0..7, written as columns: dst[j][s] = in[s * stride + j]
// (in registers: the scalar copy of a buffer's flush cost an eighth of the conservative run).
inline void Transpose8x8(const double* in, int64_t stride, double* const* dst) {
  __m512d r[8], t[8], u[8];
  for (int s = 0; s < 8; ++s) r[s] = _mm512_loadu_pd(in + s * stride);
  for (int s = 0; s < 8; s += 2) {
    t[s] = _mm512_unpacklo_pd(r[s], r[s + 1]);      // columns 0 2 4 6 of rows s, s + 1
    t[s + 1] = _mm512_unpackhi_pd(r[s], r[s + 1]);  // columns 1 3 5 7
  }
  const __m512i even = _mm512_set_epi64(13, 12, 5, 4, 9, 8, 1, 0);
  const __m512i odd = _mm512_set_epi64(15, 14, 7, 6, 11, 10, 3, 2);
  for (int h = 0; h < 8; h += 4)
    for (int k = 0; k < 2; ++k) {
      u[h + k] = _mm512_permutex2var_pd(t[h + k], even, t[h + k + 2]);      // columns k, k + 4 of 4 rows
      u[h + k + 2] = _mm512_permutex2var_pd(t[h + k], odd, t[h + k + 2]);  // columns k + 2, k + 6
    }
  const __m512i low = _mm512_set_epi64(11, 10, 9, 8, 3, 2, 1, 0);
  const __m512i high = _mm512_set_epi64(15, 14, 13, 12, 7, 6, 5, 4);
  for (int k = 0; k < 4; ++k) {  // u[k]: columns k and k + 4 of rows 0-3; u[k + 4]: of rows 4-7
    _mm512_storeu_pd(dst[k], _mm512_permutex2var_pd(u[k], low, u[k + 4]));
    _mm512_storeu_pd(dst[k + 4], _mm512_permutex2var_pd(u[k], high, u[k + 4]));
  }
}
#endif

// The samples of a block's recorded channels, (sets, n_channels, kSampleBuffer, kLanes):
// a sample's lanes side by side (contiguous stores in the step), written out every
// kSampleBuffer samples as one cache line per chain and channel.
template <int64_t kLanes>
struct SampleBuffer {
  int64_t n_channels, sets, valid, buffered = 0, written = 0;  // valid: the block's real chains
  std::vector<double> data;
  SampleBuffer(int64_t n_channels_, int64_t sets_, int64_t valid_)
      : n_channels(n_channels_), sets(sets_), valid(valid_), data(sets_ * n_channels_ * kSampleBuffer * kLanes) {}
  // the lanes of set `set`, channel c at the current sample
  double* slot(int64_t set, int64_t c) { return &data[((set * n_channels + c) * kSampleBuffer + buffered) * kLanes]; }
  // `out(set, c, j)`: where the trace of lane j's chain, channel c (set `set`), starts
  template <class Out>
  void advance(Out out) {
    if (++buffered == kSampleBuffer) flush(out);
  }
  template <class Out>
  void flush(Out out) {
    for (int64_t set = 0; set < sets; ++set)
      for (int64_t c = 0; c < n_channels; ++c) {
        const double* in = &data[(set * n_channels + c) * kSampleBuffer * kLanes];
#ifdef __AVX512F__
        if (kLanes % 8 == 0 && buffered == 8 && valid == kLanes) {  // whole: 8 x 8 transposes
          for (int64_t j0 = 0; j0 < kLanes; j0 += 8) {
            double* dst[8];
            for (int64_t j = 0; j < 8; ++j) dst[j] = out(set, c, j0 + j) + written;
            Transpose8x8(in + j0, kLanes, dst);
          }
          continue;
        }
#endif
        for (int64_t j = 0; j < valid; ++j) {
          double* dst = out(set, c, j) + written;
          for (int64_t s = 0; s < buffered; ++s) dst[s] = in[s * kLanes + j];
        }
      }
    written += buffered;
    buffered = 0;
  }
};

// One contact of the conservative sweep over a block's lanes: the drift of body i + 1, the
// force of contact i (stored in `record` when given), the full kick of body i. kUniformK /
// kUniformM: kappa / the inverse mass of the row is one value for every lane.
template <int64_t kLanes, bool kPreload, bool kSprings, bool kBooks, bool kUniformK, bool kUniformM, bool kRecord>
inline void ConservativeContact(double dt, double h, double* __restrict xi, double* __restrict xn,
                                const double* __restrict un, double* __restrict ui,
                                const double* __restrict k, const double* __restrict o,
                                const double* __restrict sp, const double* __restrict m,
                                const double* __restrict e, double* __restrict top,
                                double* __restrict force_before, double* __restrict record) {
  const double k0 = k[0], m0 = m[0];
  ForLanes<kLanes>([&](int64_t j) HC_LANES {
    xn[j] = xn[j] + dt * un[j];
    double overlap = kPreload ? (xi[j] - xn[j]) + o[j] : xi[j] - xn[j];
    double force = hertzchain::ElasticForce<kSprings>(overlap, kUniformK ? k0 : k[j], sp[j]);
    if (kBooks) top[j] = std::max(top[j], overlap);
    if (kRecord) record[j] = force;
    double body = force_before[j] - force;
    if (kPreload) body = body + e[j];
    double a = body * (kUniformM ? m0 : m[j]);
    double v = ui[j] + h * a;
    ui[j] = v + h * a;
    force_before[j] = force;
  });
}

template <int64_t kLanes, bool kPreload, bool kSprings, bool kBooks>
void RunBlock(int64_t bodies, int64_t lo, int64_t batch, int64_t n_samples,
              int64_t steps_per_sample, double dt, const double* state0, Param inv_mass,
              Param kappa, Param overlap0, Param spring, Param external,
              const std::vector<int64_t>& channels, double* state,
              const std::vector<double*>& traces) {
  const int64_t rows_x = bodies + 1, contacts = bodies;
  const double h = 0.5 * dt;
  const int64_t n_channels = static_cast<int64_t>(channels.size());
  std::vector<double> x(rows_x * kLanes), u(rows_x * kLanes), mx(contacts * kLanes);
  std::vector<double> inv(rows_x * kLanes), kap(contacts * kLanes), ov0(contacts * kLanes);
  std::vector<double> spr(contacts * kLanes), ext(rows_x * kLanes);
  Load<kLanes>({state0, batch}, rows_x, lo, x.data());
  Load<kLanes>({state0 + rows_x * batch, batch}, rows_x, lo, u.data());
  if (kBooks) Load<kLanes>({state0 + 2 * rows_x * batch, batch}, contacts, lo, mx.data());
  Load<kLanes>(inv_mass, rows_x, lo, inv.data());
  Load<kLanes>(kappa, contacts, lo, kap.data());
  Load<kLanes>(overlap0, contacts, lo, ov0.data());
  Load<kLanes>(spring, contacts, lo, spr.data());
  Load<kLanes>(external, rows_x, lo, ext.data());
  const std::vector<char> uniform_k = UniformRows<kLanes>(kap.data(), contacts);
  const std::vector<char> uniform_m = UniformRows<kLanes>(inv.data(), rows_x);
  // the channel recording each contact (-1: none); a contact recorded twice is copied
  std::vector<int64_t> channel_of(contacts, -1);
  for (int64_t c = n_channels - 1; c >= 0; --c) channel_of[channels[c]] = c;

  double force_before[kLanes];
  SampleBuffer<kLanes> record(n_channels, 1, kLanes);
  auto out = [&](int64_t, int64_t c, int64_t j) { return traces[c] + (lo + j) * n_samples; };

  for (int64_t n = 0; n < n_samples; ++n) {
    for (int64_t s = 0; s < steps_per_sample; ++s) {
      // Drift of the striker, then, body by body, the drift of the next body, the force
      // of the contact between them and the full kick of this body (v = u + h a, then
      // u = v + h a, as the JAX kernel rounds them). The forces of the sample's last step
      // are the recorded ones (of the new displacements, as the JAX kernel records them).
      const bool last = s == steps_per_sample - 1;
      for (int64_t j = 0; j < kLanes; ++j) {
        x[j] = x[j] + dt * u[j];
        force_before[j] = 0.0;
      }
      for (int64_t i = 0; i < contacts; ++i) {
        double* dst = last && channel_of[i] >= 0 ? record.slot(0, channel_of[i]) : nullptr;
        auto sweep = [&](auto uk, auto um, auto rec) {
          ConservativeContact<kLanes, kPreload, kSprings, kBooks, decltype(uk)::value, decltype(um)::value,
                              decltype(rec)::value>(
              dt, h, &x[i * kLanes], &x[(i + 1) * kLanes], &u[(i + 1) * kLanes], &u[i * kLanes], &kap[i * kLanes],
              &ov0[i * kLanes], &spr[i * kLanes], &inv[i * kLanes], &ext[i * kLanes], &mx[i * kLanes],
              force_before, dst);
        };
        using T = std::true_type;
        using F = std::false_type;
        const int which = (uniform_k[i] ? 4 : 0) + (uniform_m[i] ? 2 : 0) + (dst ? 1 : 0);
        switch (which) {
          case 0: sweep(F{}, F{}, F{}); break;
          case 1: sweep(F{}, F{}, T{}); break;
          case 2: sweep(F{}, T{}, F{}); break;
          case 3: sweep(F{}, T{}, T{}); break;
          case 4: sweep(T{}, F{}, F{}); break;
          case 5: sweep(T{}, F{}, T{}); break;
          case 6: sweep(T{}, T{}, F{}); break;
          default: sweep(T{}, T{}, T{}); break;
        }
      }
      // The wall's row (inverse mass 0: it stays at rest, as in the JAX kernel).
      double* uw = &u[contacts * kLanes];
      const double* mw = &inv[contacts * kLanes];
      const double* ew = &ext[contacts * kLanes];
      for (int64_t j = 0; j < kLanes; ++j) {
        double body = force_before[j];
        if (kPreload) body = body + ew[j];
        double a = body * mw[j];
        double v = uw[j] + h * a;
        uw[j] = v + h * a;
      }
    }
    // a contact recorded by two channels: the second a copy of the first
    for (int64_t c = 0; c < n_channels; ++c)
      if (channel_of[channels[c]] != c) std::copy_n(record.slot(0, channel_of[channels[c]]), kLanes, record.slot(0, c));
    record.advance(out);
  }
  if (record.buffered) record.flush(out);

  auto store = [&](const std::vector<double>& block, int64_t rows, double* dst) {
    for (int64_t r = 0; r < rows; ++r)
      for (int64_t j = 0; j < kLanes; ++j) dst[r * batch + lo + j] = block[r * kLanes + j];
  };
  store(x, rows_x, state);
  store(u, rows_x, state + rows_x * batch);
  if (kBooks) store(mx, contacts, state + 2 * rows_x * batch);
}

// ---------------------------------------------------------------------------------------
// The full step of `batched._step` (velocities and accelerations kept apart): Kuwabara-Kono
// damping at every contact (`contact.contact_force`: the total force clipped at 0) and
// track friction (`contact.track_friction_kick`) before the drift and after the second half
// kick, with sensor springs, static overlaps and external forces of a preload (zeros where
// there are none: adding 0 changes no bit). kViscous and kFriction select the physics at
// compile time; kTangent adds forward-mode tangents: the derivatives of every state variable
// along `directions` tangent directions of the inputs, carried through the same loop: the
// partial derivatives of every contact's force, friction kick and largest overlap are those
// laws of `chain_laws.h` run on dual numbers once per step (the rules JAX's jvp applies to
// the JAX kernel), and each direction's tangent their sum over the inputs' tangents, so that
// the two kernels agree to round-off.
//   state0 (3 (bodies + 1), B): x, v, a; parameters (rows, 1 or B); eta, friction (1, 1 or B).
//   Tangents: every input with a leading direction axis, (D, rows, B) or (1, rows, B); results:
//   the traces (B, n_samples), then their tangents (D, B, n_samples), from one run.

// The contacts' elastic law of a full run (`batched.KernelFlags.law`): each library runs one
// (the main and dashpot libraries Hertz's, HC_POWER_LIBRARY the power law, HC_THORNTON_LIBRARY
// and HC_JACKSON_GREEN_LIBRARY the elastic-plastic laws).
enum class Law { kHertz, kPower, kThornton, kJacksonGreen };

// Whether a law is elastic-plastic: its contacts carry their largest overlap so far.
constexpr bool IsPlastic(Law law) { return law == Law::kThornton || law == Law::kJacksonGreen; }

// Rows of the `law` array (1 or B columns): Hertz's runs read none (2 rows of zeros); the
// power law its exponent and reference overlap (m); Thornton's law every contact's yield
// force (N; infinite: elastic); Jackson-Green's every contact's yield force (whether it
// yields), reduced radius (m) and Poisson ratio, then the chain's yield stress (Pa) and
// hardness ratio.
constexpr int64_t LawRows(Law law, int64_t contacts) {
  return law == Law::kThornton ? contacts : law == Law::kJacksonGreen ? 3 * contacts + 2 : 2;
}

// Rows of the `sensors` array of n compliant sensors (`compliant_sensor`; 1 or B columns):
// each sensor's front-half mass fraction beta, then its 1/omega0^2 (s^2), its back and front
// compliances (m/N), n rows each, then the preload's force on the first bead (N), from which
// a sensor's compression is counted.
constexpr int64_t SensorRows(int64_t sensors) { return 4 * sensors + 1; }

struct FullParams {
  Param inv_mass, kappa, overlap0, spring, external, eta, friction, dashpot;
  Param law;      // the law's parameters (`LawRows`)
  Param sensors;  // the compliant sensors' (`SensorRows`; the sensor library's runs)
  const int64_t* beads = nullptr;  // their beads K (back contact K - 1, front contact K)
  int64_t n_sensors = 0;
};

struct TangentInputs {
  Tangent state0;  // x, v, a (and the sensors' force, rate, drive): (D, 3 (bodies + 1) + 3 n, B)
  Tangent inv_mass, kappa, overlap0, spring, external, eta, friction, dashpot, law, sensors;
};

// The books of a forward run (kBooks), in `batched._Layout`'s rows after x, v, a (and, for
// elastic-plastic contacts, every contact's largest overlap so far): the largest total force of every contact so far (bodies rows), with damping the viscous force
// on every body and the wall (bodies + 1), and the energy dissipated so far (1); `state0`
// in, `state` out (the whole packed state, x, v, a first), `mass` (bodies, 1 or B) for the
// energy friction takes.
struct BooksIO {
  const double* state0;
  Param mass;
  double* state;
};

// The unloading curve of an elastic-plastic contact (`hertzchain::Unloading`) from its inputs
// `in`: the largest overlap so far (m), kappa, then the law's own (Thornton: the yield force;
// Jackson-Green: reduced radius, yield stress, Poisson ratio, hardness ratio), and, where
// `slopes` is given, the partial derivatives of the residual overlap (first) and of the
// stiffness (then) by each input. Out of line: compiled once per library, not once per
// variant of the kernel (a third of the library's build time), and called only when a
// contact's largest overlap grows.
template <Law kLaw>
__attribute__((noinline)) hertzchain::Unloading<double> PlasticCurve(const double* in, double* slopes) {
  constexpr int kN = kLaw == Law::kJacksonGreen ? 6 : 3;
  if (slopes != nullptr) {
    hertzchain::Dual<kN> x[kN];
    for (int k = 0; k < kN; ++k) x[k] = hertzchain::Input<kN>(in[k], k);
    hertzchain::Unloading<hertzchain::Dual<kN>> t;
    if constexpr (kLaw == Law::kThornton)
      t = hertzchain::ThorntonUnloading(x[0], x[1], x[2]);
    else
      t = hertzchain::JacksonGreenUnloading(x[0], x[1], x[2], x[3], x[4], x[5]);
    for (int k = 0; k < kN; ++k) {
      slopes[k] = t.residual.d[k];
      slopes[kN + k] = t.kappa.d[k];
    }
    return {t.residual.v, t.kappa.v};
  }
  if constexpr (kLaw == Law::kThornton) return hertzchain::ThorntonUnloading<double>(in[0], in[1], in[2]);
  return hertzchain::JacksonGreenUnloading<double>(in[0], in[1], in[2], in[3], in[4], in[5]);
}

template <int64_t kLanes, bool kViscous, bool kFriction, bool kTangent, bool kExtras, bool kDashpot, bool kBooks,
          Law kLaw, bool kSensors>
void RunFullBlock(int64_t bodies, int64_t lo, int64_t batch, int64_t n_samples,
                  int64_t steps_per_sample, double dt, const double* state0, FullParams p,
                  const std::vector<int64_t>& channels, const std::vector<double*>& traces,
                  int64_t directions, TangentInputs tin, const std::vector<double*>& ttraces, BooksIO books) {
  static_assert(!(kBooks && kTangent), "the books are kept by forward runs only");
  static_assert(!kSensors || !kBooks, "compliant sensors: no books");
  constexpr bool kPower = kLaw == Law::kPower;
  constexpr bool kPlastic = IsPlastic(kLaw);
  const int64_t rows_x = bodies + 1, contacts = bodies;
  const int64_t law_rows = LawRows(kLaw, contacts);
  const double h = 0.5 * dt;
  const int64_t n_channels = static_cast<int64_t>(channels.size());
  const int64_t D = kTangent ? directions : 0;
  const int64_t valid = std::min(kLanes, batch - lo);  // a last, partial block repeats its last chain
  std::vector<double> x(rows_x * kLanes), v(rows_x * kLanes), a(rows_x * kLanes);
  std::vector<double> inv(rows_x * kLanes), kap(contacts * kLanes), ov0(contacts * kLanes);
  std::vector<double> spr(contacts * kLanes), ext(rows_x * kLanes), eta(kLanes), fr(kLanes), dash(kLanes);
  Load<kLanes>({state0, batch}, rows_x, lo, x.data(), valid);
  Load<kLanes>({state0 + rows_x * batch, batch}, rows_x, lo, v.data(), valid);
  Load<kLanes>({state0 + 2 * rows_x * batch, batch}, rows_x, lo, a.data(), valid);
  Load<kLanes>(p.inv_mass, rows_x, lo, inv.data(), valid);
  Load<kLanes>(p.kappa, contacts, lo, kap.data(), valid);
  Load<kLanes>(p.overlap0, contacts, lo, ov0.data(), valid);
  Load<kLanes>(p.spring, contacts, lo, spr.data(), valid);
  Load<kLanes>(p.external, rows_x, lo, ext.data(), valid);
  Load<kLanes>(p.eta, 1, lo, eta.data(), valid);
  Load<kLanes>(p.friction, 1, lo, fr.data(), valid);
  if (kDashpot) Load<kLanes>(p.dashpot, 1, lo, dash.data(), valid);
  // kSensors: the compliant sensors (`compliant_sensor`, `batched._step`): their forces (N),
  // rates (N/s) and drives (Eq. 4, N) after x, v, a in state0 (n rows each), their
  // parameters `sp` (`SensorRows`); per step the half-step rates, the predicted rates, the
  // compressions counted from the preload's force (F_s - F_0) and whether the step resolves
  // the resonance (`compliant_sensor.drift`), and the total forces of their back and front
  // contacts (the next drive). `back_of[i]` / `front_of[i]`: the sensor whose back / front
  // contact is contact i (-1: none). `cut` / `cut_rate`: what the sensors take from every
  // contact's overlap (m) and rate (m/s) in the step (`compliant_sensor.shortened`; 0 for
  // the contacts without a sensor: adding 0 changes no bit; a contact between two sensors
  // loses the back's term, then the front's).
  const int64_t ns = kSensors ? p.n_sensors : 0;
  const int64_t sensor_rows = kSensors ? SensorRows(ns) : 0;
  std::vector<double> sf(ns * kLanes), sr(ns * kLanes), sd(ns * kLanes), sp(sensor_rows * kLanes);
  std::vector<double> s_half(ns * kLanes), s_pred(ns * kLanes), s_amt(ns * kLanes), s_quasi(ns * kLanes);
  std::vector<double> s_fb(ns * kLanes), s_ff(ns * kLanes);
  std::vector<double> cut(kSensors ? contacts * kLanes : 0), cut_rate(kSensors ? contacts * kLanes : 0);
  std::vector<int64_t> back_of(kSensors ? contacts : 0, -1), front_of(kSensors ? contacts : 0, -1);
  if constexpr (kSensors) {
    const double* s0 = state0 + 3 * rows_x * batch;
    Load<kLanes>({s0, batch}, ns, lo, sf.data(), valid);
    Load<kLanes>({s0 + ns * batch, batch}, ns, lo, sr.data(), valid);
    Load<kLanes>({s0 + 2 * ns * batch, batch}, ns, lo, sd.data(), valid);
    Load<kLanes>(p.sensors, sensor_rows, lo, sp.data(), valid);
    for (int64_t k = 0; k < ns; ++k) {
      back_of[p.beads[k] - 1] = k;
      front_of[p.beads[k]] = k;
    }
  }
  // rows of `sp` (and of its tangents, direction by direction)
  const auto beta_row = [&](int64_t k) { return k; };
  const auto inv_row = [&](int64_t k) { return ns + k; };
  const auto back_row = [&](int64_t k) { return 2 * ns + k; };
  const auto front_row = [&](int64_t k) { return 3 * ns + k; };
  const int64_t first_row = 4 * ns;
  const double dt2 = dt * dt;
  // kPower: every contact's law is `contact.power_law_force` of the chain's exponent (row 0)
  // and reference overlap (row 1); kPlastic: the rows of `LawRows`
  std::vector<double> law(kPower || kPlastic ? law_rows * kLanes : 0);
  if (kPower || kPlastic) Load<kLanes>(p.law, law_rows, lo, law.data(), valid);
  // 1.5 eta kappa and (kDashpot) the dashpot (`hertzchain::ContactDashpot`) of every contact
  std::vector<double> kvis(contacts * kLanes), dsh(contacts * kLanes);
  for (int64_t i = 0; i < contacts; ++i)
    for (int64_t j = 0; j < kLanes; ++j) {
      kvis[i * kLanes + j] = 1.5 * eta[j] * kap[i * kLanes + j];
      if (kDashpot) dsh[i * kLanes + j] = hertzchain::ContactDashpot(kap[i * kLanes + j], dash[j]);
    }
  // the books (kBooks): `top` the largest total force of every contact, `vis` the viscous
  // force on every body (damping), `spent` the energy dissipated, `mass` (friction)
  const int64_t peak_row = 3 * rows_x, top_row = peak_row + (kPlastic ? contacts : 0);
  const int64_t vis_row = top_row + contacts, spent_row = vis_row + (kViscous ? rows_x : 0);
  std::vector<double> top(kBooks ? contacts * kLanes : 0), vis(kBooks && kViscous ? rows_x * kLanes : 0);
  std::vector<double> mass(kBooks && kFriction ? contacts * kLanes : 0), spent(kBooks ? kLanes : 0);
  double damped[kLanes];  // 1 where the chain is damped: an undamped one's viscous work is 0, exactly
  if constexpr (kBooks) {
    Load<kLanes>({state0 + top_row * batch, batch}, contacts, lo, top.data(), valid);
    if (kViscous) Load<kLanes>({state0 + vis_row * batch, batch}, rows_x, lo, vis.data(), valid);
    Load<kLanes>({state0 + spent_row * batch, batch}, 1, lo, spent.data(), valid);
    if (kFriction) Load<kLanes>(books.mass, contacts, lo, mass.data(), valid);
    for (int64_t j = 0; j < kLanes; ++j) damped[j] = eta[j] != 0.0 || (kDashpot && dash[j] != 0.0) ? 1.0 : 0.0;
  }
  // per step and lane: the viscous work of the two half steps, the kinetic energy the two
  // friction kicks took (sums over the bodies, in `batched._step`'s order), the unkicked
  // half-step velocity of body i and the viscous part of the force of contact i - 1
  double work1[kLanes], work2[kLanes], lost1[kLanes], lost2[kLanes], raw_prev[kLanes], d_prev[kLanes];
  // tangents (D, rows, kLanes)
  std::vector<double> tx(D * rows_x * kLanes), tv(D * rows_x * kLanes), ta(D * rows_x * kLanes);
  std::vector<double> tinv(D * rows_x * kLanes), tkap(D * contacts * kLanes), tov0(D * contacts * kLanes);
  std::vector<double> tspr(D * contacts * kLanes), text(D * rows_x * kLanes), teta(D * kLanes), tfr(D * kLanes);
  std::vector<double> tdash(D * kLanes);
  if (kTangent) {
    for (int64_t d = 0; d < D; ++d) {
      const double* s0 = tin.state0.data + (tin.state0.shared ? 0 : d * (3 * rows_x + 3 * ns) * batch);
      Load<kLanes>({s0, batch}, rows_x, lo, &tx[d * rows_x * kLanes], valid);
      Load<kLanes>({s0 + rows_x * batch, batch}, rows_x, lo, &tv[d * rows_x * kLanes], valid);
      Load<kLanes>({s0 + 2 * rows_x * batch, batch}, rows_x, lo, &ta[d * rows_x * kLanes], valid);
    }
    LoadTangent<kLanes>(tin.inv_mass, D, rows_x, batch, lo, tinv.data(), valid);
    LoadTangent<kLanes>(tin.kappa, D, contacts, batch, lo, tkap.data(), valid);
    LoadTangent<kLanes>(tin.overlap0, D, contacts, batch, lo, tov0.data(), valid);
    LoadTangent<kLanes>(tin.spring, D, contacts, batch, lo, tspr.data(), valid);
    LoadTangent<kLanes>(tin.external, D, rows_x, batch, lo, text.data(), valid);
    LoadTangent<kLanes>(tin.eta, D, 1, batch, lo, teta.data(), valid);
    LoadTangent<kLanes>(tin.friction, D, 1, batch, lo, tfr.data(), valid);
    if (kDashpot) LoadTangent<kLanes>(tin.dashpot, D, 1, batch, lo, tdash.data(), valid);
  }
  // Whether no direction moves this block's inverse masses and stiffnesses nor, with
  // kExtras, its preload's overlaps, springs or external forces (a fit of damping, friction
  // and impact speed): the sweep then seeds neither kappa nor the spring (the dual numbers
  // carry fewer partials) and its tangent pass leaves their terms out (products with 0: no
  // value changes) and reads a third fewer rows.
  const auto all_zero = [](const std::vector<double>& rows) {
    return std::all_of(rows.begin(), rows.end(), [](double t) { return t == 0.0; });
  };
  const bool fixed_inputs =
      kTangent && all_zero(tinv) && all_zero(tkap) &&
      (!kExtras || (all_zero(tov0) && all_zero(tspr) && all_zero(text)));
  // kSensors: the tangents of the sensors' state and parameters, (D, rows, kLanes), and of
  // the step's half-step rates, predicted rates, compressions, contact forces and cuts
  std::vector<double> tsf(D * ns * kLanes), tsr(D * ns * kLanes), tsd(D * ns * kLanes);
  std::vector<double> tsp(D * sensor_rows * kLanes), ts_half(D * ns * kLanes), ts_pred(D * ns * kLanes);
  std::vector<double> ts_amt(D * ns * kLanes), ts_fb(D * ns * kLanes), ts_ff(D * ns * kLanes);
  std::vector<double> tcut(kSensors ? D * contacts * kLanes : 0), tcut_rate(kSensors ? D * contacts * kLanes : 0);
  if (kTangent && kSensors) {
    for (int64_t d = 0; d < D; ++d) {
      const double* s0 = tin.state0.data + (tin.state0.shared ? 0 : d * (3 * rows_x + 3 * ns) * batch) +
                         3 * rows_x * batch;
      Load<kLanes>({s0, batch}, ns, lo, &tsf[d * ns * kLanes], valid);
      Load<kLanes>({s0 + ns * batch, batch}, ns, lo, &tsr[d * ns * kLanes], valid);
      Load<kLanes>({s0 + 2 * ns * batch, batch}, ns, lo, &tsd[d * ns * kLanes], valid);
    }
    LoadTangent<kLanes>(tin.sensors, D, sensor_rows, batch, lo, tsp.data(), valid);
  }
  // the sensors' tangent rows of direction d
  const auto tsens = [&](int64_t d, int64_t row) { return &tsp[(d * sensor_rows + row) * kLanes]; };
  std::vector<double> tlaw(kPower || kPlastic ? D * law_rows * kLanes : 0);  // (D, law_rows, kLanes)
  if (kTangent && (kPower || kPlastic)) {
    LoadTangent<kLanes>(tin.law, D, law_rows, batch, lo, tlaw.data(), valid);
  }
  // kPlastic: every contact's largest overlap so far (`peak`, m; the state's with the books,
  // else the overlaps at the start, as `batched._initial_peak` has them) and the unloading
  // curve it leaves (`hertzchain::Unloading`: residual overlap `res`, stiffness `kpl`);
  // `yields` 1 where the contact's law is plastic (a finite yield force; for Jackson-Green's
  // law, and a contact law: `forces.elastic_parts`), else Hertz's. With kTangent, the partial
  // derivatives of (res, kpl) by the law's inputs (`kInputs`: the peak, kappa, then the
  // law's own, `PlasticInputs`) and the peaks' tangents (D, contacts, kLanes).
  constexpr int kInputs = kLaw == Law::kJacksonGreen ? 6 : 3;
  const int64_t plastic_size = kPlastic ? contacts * kLanes : 0;
  std::vector<double> pk(plastic_size), res(plastic_size), kpl(plastic_size), yields(plastic_size);
  std::vector<double> dres(kTangent ? kInputs * plastic_size : 0), dkpl(kTangent ? kInputs * plastic_size : 0);
  std::vector<double> tpk(kTangent ? D * plastic_size : 0);
  // the unloading curve of contact index c = i kLanes + j (and its partials) at its peak
  auto unload = [&](int64_t i, int64_t j) {
    const int64_t c = i * kLanes + j;
    if (yields[c] == 0.0) {
      res[c] = 0.0;
      kpl[c] = kap[c];
      if constexpr (kTangent)
        for (int k = 0; k < kInputs; ++k) {
          dres[k * plastic_size + c] = 0.0;
          dkpl[k * plastic_size + c] = k == 1 ? 1.0 : 0.0;
        }
      return;
    }
    double in[kInputs], slopes[2 * kInputs];  // `PlasticCurve`'s inputs and partials
    in[0] = pk[c];
    in[1] = kap[c];
    if constexpr (kLaw == Law::kThornton) {
      in[2] = law[c];  // the yield force
    } else {
      in[2] = law[(contacts + i) * kLanes + j];        // reduced radius
      in[3] = law[3 * contacts * kLanes + j];          // yield stress
      in[4] = law[(2 * contacts + i) * kLanes + j];    // Poisson ratio
      in[5] = law[(3 * contacts + 1) * kLanes + j];    // hardness ratio
    }
    const hertzchain::Unloading<double> u = PlasticCurve<kLaw>(in, kTangent ? slopes : nullptr);
    res[c] = u.residual;
    kpl[c] = u.kappa;
    if constexpr (kTangent)
      for (int k = 0; k < kInputs; ++k) {
        dres[k * plastic_size + c] = slopes[k];
        dkpl[k * plastic_size + c] = slopes[kInputs + k];
      }
  };
  // the tangent of input k of contact i, lane j, along direction d (`kInputs`' order)
  auto plastic_input = [&](int k, int64_t d, int64_t i, int64_t j) {
    if (k == 0) return tpk[(d * contacts + i) * kLanes + j];
    if (k == 1) return tkap[(d * contacts + i) * kLanes + j];
    const double* t = &tlaw[d * law_rows * kLanes];
    if constexpr (kLaw == Law::kThornton) return t[i * kLanes + j];  // the yield force
    if (k == 2) return t[(contacts + i) * kLanes + j];                // reduced radius
    if (k == 3) return t[3 * contacts * kLanes + j];                  // yield stress
    if (k == 4) return t[(2 * contacts + i) * kLanes + j];            // Poisson ratio
    return t[(3 * contacts + 1) * kLanes + j];                        // hardness ratio
  };
  if constexpr (kPlastic) {
    if constexpr (kBooks) {
      Load<kLanes>({state0 + peak_row * batch, batch}, contacts, lo, pk.data(), valid);
    } else {
      for (int64_t i = 0; i < contacts; ++i)
        for (int64_t j = 0; j < kLanes; ++j)
          pk[i * kLanes + j] = kExtras ? x[i * kLanes + j] - x[(i + 1) * kLanes + j] + ov0[i * kLanes + j]
                                       : x[i * kLanes + j] - x[(i + 1) * kLanes + j];
      if constexpr (kTangent)
        for (int64_t d = 0; d < D; ++d)
          for (int64_t i = 0; i < contacts; ++i)
            for (int64_t j = 0; j < kLanes; ++j)
              tpk[(d * contacts + i) * kLanes + j] =
                  kExtras ? tx[(d * rows_x + i) * kLanes + j] - tx[(d * rows_x + i + 1) * kLanes + j] +
                                tov0[(d * contacts + i) * kLanes + j]
                          : tx[(d * rows_x + i) * kLanes + j] - tx[(d * rows_x + i + 1) * kLanes + j];
    }
    for (int64_t i = 0; i < contacts; ++i)
      for (int64_t j = 0; j < kLanes; ++j) {
        const int64_t c = i * kLanes + j;
        const bool finite = std::isfinite(law[c]);
        yields[c] = (kLaw == Law::kJacksonGreen ? finite && kap[c] > 0.0 : finite) ? 1.0 : 0.0;
        unload(i, j);
      }
  }
  // recorded sets: the forces, then (kTangent) their tangent along every direction
  const int64_t out_sets = 1 + D;
  SampleBuffer<kLanes> record(n_channels, out_sets, valid);
  auto out = [&](int64_t set, int64_t c, int64_t j) {
    return set == 0 ? traces[c] + (lo + j) * n_samples : ttraces[c] + ((set - 1) * batch + lo + j) * n_samples;
  };
  // rows whose kappa and 1.5 eta kappa, or inverse mass, are one value for every lane
  std::vector<char> uniform_k = UniformRows<kLanes>(kap.data(), contacts);
  const std::vector<char> uniform_kv = UniformRows<kLanes>(kvis.data(), contacts);
  const std::vector<char> uniform_d = UniformRows<kLanes>(dsh.data(), contacts);
  const std::vector<char> uniform_m = UniformRows<kLanes>(inv.data(), rows_x);
  for (int64_t i = 0; i < contacts; ++i) uniform_k[i] = uniform_k[i] && uniform_kv[i] && (!kDashpot || uniform_d[i]);

  // Per-lane values of the step kept for the tangent pass: what does not depend on the
  // direction is computed once per contact and step, not once per direction.
  double loss[kLanes];              // mu g dt/2
  double w_prev[kLanes], p_prev[kLanes], f_prev[kLanes];  // body i: kicked half-step and predicted velocity; force before
  double c1[kLanes];                // 1.5 eta
  // the two friction kicks' partial derivatives by the velocity kicked and by the loss
  double kick1_w[kLanes], kick1_loss[kLanes], kick2_w[kLanes], kick2_loss[kLanes];
  double body[kLanes];              // the force on body i
  // The inputs of a contact's force in the tangent runs, in the order of its partial
  // derivatives (`force_slopes`): the overlap (m) and kappa, with damping the rate (m/s) and
  // 1.5 eta (s), with a dashpot the chain's dashpot (N s/m), with the extras the spring
  // (N/m), then the law's own two: the power law's exponent and reference overlap (m), an
  // elastic-plastic contact's residual overlap (m) and unloading stiffness (N/m^1.5).
  constexpr int kOverlapIn = 0, kKappaIn = 1, kRateIn = 2, kEtaIn = 3;
  constexpr int kDashIn = kViscous ? 4 : 2, kSpringIn = kDashIn + (kDashpot ? 1 : 0);
  constexpr int kLawIn = kSpringIn + (kExtras ? 1 : 0);
  constexpr int kForceInputs = kLawIn + (kPower || kPlastic ? 2 : 0);
  double force_slopes[kForceInputs * kLanes];  // contact i's, (kForceInputs, kLanes)
  // tangents of w_prev, p_prev, f_prev and per-direction constants (D, kLanes)
  std::vector<double> tw_prev(D * kLanes), tp_prev(D * kLanes), tf_prev(D * kLanes);
  std::vector<double> tloss(D * kLanes), t15eta(D * kLanes);
  for (int64_t j = 0; j < kLanes; ++j) {
    loss[j] = fr[j] * h;
    c1[j] = 1.5 * eta[j];
  }
  for (int64_t q = 0; q < D * kLanes; ++q) {
    tloss[q] = tfr[q] * h;
    t15eta[q] = 1.5 * teta[q];
  }

  // contact.track_friction_kick (`kick`) as `chain_laws.h` has it, and (`kick_slopes`) with
  // its partial derivatives by the velocity and the loss (the law run on dual numbers)
  const auto kick = [](double w, double loss_j) HC_LANES { return hertzchain::Kick(w, loss_j); };
  const auto kick_slopes = [](double w, double loss_j, double* by_w, double* by_loss) HC_LANES {
    const auto kicked = hertzchain::Kick(hertzchain::Seed<2, 0>(w), hertzchain::Seed<2, 1>(loss_j));
    *by_w = hertzchain::Slope(kicked, 0);
    *by_loss = hertzchain::Slope(kicked, 1);
    return kicked.v;
  };
  // The force of a contact with the chain's law (`contact.contact_force`: `DampedTotal` about
  // Hertz's elastic force, with kPower the power law's, with kPlastic Hertz's about the
  // unloading curve): at overlap dl, rate, kappa k, 1.5 eta kappa kv (computed once per block
  // as JAX rounds it: (1.5 eta) kappa), dashpot d (`ContactDashpot`), spring sp and the law's
  // two inputs (`kLawIn`); `elastic`, where given, receives the law's elastic force (the
  // books read it). Any number types: doubles for the values, duals for the partials.
  const auto law_force = [](const auto& dl, const auto& rate, const auto& k, const auto& kv, const auto& d,
                            const auto& sp, const auto& law0, const auto& law1, double* elastic) HC_LANES {
    const auto positive = hertzchain::PositivePart(dl);
    const auto rt = hertzchain::RootOfPositive(positive);
    const auto own = [&]() HC_LANES {
      if constexpr (kPlastic) {
        return hertzchain::UnloadingForce(dl, law0, law1);
      } else if constexpr (kPower) {
        return hertzchain::PowerLawForce(dl, k, law0, law1);
      } else {
        return hertzchain::HertzElastic(k, positive, rt);
      }
    }();
    if (elastic != nullptr) *elastic = hertzchain::Value(own);
    return hertzchain::DampedTotal<kViscous, kExtras, kDashpot>(own, rt, dl, rate, kv, d, sp);
  };
  // the law's two inputs of contact index c, lane j (kPower: the chain's exponent and
  // reference overlap; kPlastic: the contact's unloading curve; Hertz's law reads none)
  const auto law_in = [&](int64_t c, int64_t j, int which) HC_LANES {
    if constexpr (kPlastic) return which == 0 ? res[c] : kpl[c];
    if constexpr (kPower) return law[which * kLanes + j];
    return 0.0;
  };
  // The force of contact index c at lane j and its partial derivatives by its inputs
  // (`kForceInputs`, into `slopes[q * stride]`): `law_force` run on dual numbers seeded with
  // each input, kappa and the spring only with `own_tag` (std::true_type: they have
  // tangents in this block, `fixed_inputs`); c1 the lane's 1.5 eta, dash its chain's dashpot.
  auto contact_slopes = [&](auto own_tag, double dl, double rate, double k, double c1j, double dash, double sp,
                            int64_t c, int64_t j, double* slopes, int64_t stride) HC_LANES {
    constexpr int N = kForceInputs;
    constexpr bool kOwn = decltype(own_tag)::value;
    using hertzchain::SeedIf;
    const auto kd = SeedIf<kOwn, N, kKappaIn>(k);
    const auto c1d = SeedIf<kViscous, N, kEtaIn>(c1j);
    const auto total = law_force(hertzchain::Seed<N, kOverlapIn>(dl), SeedIf<kViscous, N, kRateIn>(rate), kd,
                                 c1d * kd, hertzchain::ContactDashpot(kd, SeedIf<kDashpot, N, kDashIn>(dash)),
                                 SeedIf<kExtras && kOwn, N, kSpringIn>(sp),
                                 SeedIf<kPower || kPlastic, N, kLawIn>(law_in(c, j, 0)),
                                 SeedIf<kPower || kPlastic, N, kLawIn + 1>(law_in(c, j, 1)), nullptr);
    // the partials `force_tangent` reads: those by the seeded inputs
    constexpr unsigned kSeeded = 1u << kOverlapIn | (kOwn ? 1u << kKappaIn : 0u) |
                                 (kViscous ? 1u << kRateIn | 1u << kEtaIn : 0u) | (kDashpot ? 1u << kDashIn : 0u) |
                                 (kExtras && kOwn ? 1u << kSpringIn : 0u) | (kPower || kPlastic ? 3u << kLawIn : 0u);
    HC_UNROLL
    for (int q = 0; q < N; ++q)
      if (hertzchain::Has(kSeeded, q)) slopes[q * stride] = hertzchain::Slope(total, q);
    return total.v;
  };
  // The tangent of a contact's force along one direction from its partials (`slopes[q *
  // stride]`) and its inputs' tangents: tdl, trate, tk, t15e (1.5 eta's), tdash (the chain's
  // dashpot's), tsp, tlaw0, tlaw1; `spring_tangent` (std::true_type or false_type): whether
  // kappa's and the spring's tangents `tk`, `tsp` can be other than 0 (`contact_slopes`'
  // `own_tag`)
  auto force_tangent = [&](auto spring_tangent, const double* slopes, int64_t stride, double tdl, double trate,
                           double tk, double t15e, double tdash, double tsp, double tlaw0, double tlaw1) HC_LANES {
    constexpr bool kST = decltype(spring_tangent)::value;
    double t = slopes[kOverlapIn * stride] * tdl;
    if constexpr (kST) t = t + slopes[kKappaIn * stride] * tk;
    if constexpr (kViscous) t = t + slopes[kRateIn * stride] * trate + slopes[kEtaIn * stride] * t15e;
    if constexpr (kDashpot) t = t + slopes[kDashIn * stride] * tdash;
    if constexpr (kExtras && kST) t = t + slopes[kSpringIn * stride] * tsp;
    if constexpr (kPower || kPlastic) t = t + slopes[kLawIn * stride] * tlaw0 + slopes[(kLawIn + 1) * stride] * tlaw1;
    return t;
  };
  // the tangents of the law's two inputs of contact i, lane j, along direction d (kPlastic:
  // the residual overlap's and the stiffness's, through the unloading curve's partials by
  // the peak, kappa and the law's inputs; kPower: the exponent's and the reference's)
  auto law_tangents = [&](int64_t i, int64_t j, int64_t d, double* tlaw0, double* tlaw1) HC_LANES {
    *tlaw0 = *tlaw1 = 0.0;
    if constexpr (kPlastic) {
      for (int q = 0; q < kInputs; ++q) {
        const double t = plastic_input(q, d, i, j);
        *tlaw0 = *tlaw0 + dres[q * plastic_size + i * kLanes + j] * t;
        *tlaw1 = *tlaw1 + dkpl[q * plastic_size + i * kLanes + j] * t;
      }
    } else if constexpr (kPower) {
      *tlaw0 = tlaw[d * 2 * kLanes + j];
      *tlaw1 = tlaw[(d * 2 + 1) * kLanes + j];
    }
  };
  // kPlastic and kTangent: the partial derivatives of contact i's largest overlap so far,
  // max(peak, overlap), by the peak before and by the step's overlap (1, 1/2 or 0)
  double peak_by_old[kLanes], peak_by_overlap[kLanes];
  double fresh[kLanes];  // kPlastic: 1 where contact i's largest overlap grew and its law yields

  for (int64_t n = 0; n < n_samples; ++n) {
    for (int64_t s = 0; s < steps_per_sample; ++s) {
      if constexpr (kSensors) {  // the sensors' first half kick and drift (`compliant_sensor.drift`)
        for (int64_t k = 0; k < ns; ++k)
          for (int64_t j = 0; j < kLanes; ++j) {
            const int64_t c = k * kLanes + j;
            const double inv_w2 = sp[inv_row(k) * kLanes + j];
            const bool quasi = inv_w2 < dt2;  // the step does not resolve the resonance
            const double gap = sd[c] - sf[c];
            const double accel = quasi ? 0.0 : gap / inv_w2;
            const double half = sr[c] + h * accel;
            const double force = quasi ? sd[c] : sf[c] + dt * half;
            if constexpr (kTangent)  // (JAX's rules: d(a/b) = da/b + (-db a) b^-2)
              for (int64_t d = 0; d < D; ++d) {
                const int64_t q = (d * ns + k) * kLanes + j;
                const double tinv_w2 = tsens(d, inv_row(k))[j];
                const double taccel =
                    quasi ? 0.0 : (tsd[q] - tsf[q]) / inv_w2 + ((-tinv_w2) * gap) * (1.0 / (inv_w2 * inv_w2));
                const double thalf = tsr[q] + h * taccel;
                tsf[q] = quasi ? tsd[q] : tsf[q] + dt * thalf;
                ts_half[q] = thalf;
                ts_pred[q] = thalf + h * taccel;
                ts_amt[q] = tsf[q] - tsens(d, first_row)[j];
              }
            sf[c] = force;
            s_half[c] = half;
            s_pred[c] = half + h * accel;
            s_amt[c] = force - sp[first_row * kLanes + j];
            s_quasi[c] = quasi ? 1.0 : 0.0;
          }
        // the cuts of every sensor's back (row K - 1) and front (row K) contacts: zeroed,
        // then the backs' terms, then the fronts' (the order of `compliant_sensor.shortened`)
        for (int64_t k = 0; k < ns; ++k)
          for (const int64_t row : {p.beads[k] - 1, p.beads[k]})
            for (int64_t j = 0; j < kLanes; ++j) {
              cut[row * kLanes + j] = cut_rate[row * kLanes + j] = 0.0;
              for (int64_t d = 0; d < D; ++d)
                tcut[(d * contacts + row) * kLanes + j] = tcut_rate[(d * contacts + row) * kLanes + j] = 0.0;
            }
        for (const int64_t side : {0, 1})  // 0: the sensors' back contacts, 1: their front ones
          for (int64_t k = 0; k < ns; ++k) {
            const int64_t row = p.beads[k] - 1 + side, crow = side == 0 ? back_row(k) : front_row(k);
            for (int64_t j = 0; j < kLanes; ++j) {
              const int64_t e = k * kLanes + j, i = row * kLanes + j;
              const double comp = sp[crow * kLanes + j];
              cut[i] = cut[i] - comp * s_amt[e];
              cut_rate[i] = cut_rate[i] - comp * s_pred[e];
              for (int64_t d = 0; d < D; ++d) {  // (JAX's rule for c a: dc a + c da)
                const int64_t td = (d * contacts + row) * kLanes + j, te = (d * ns + k) * kLanes + j;
                const double tcomp = tsens(d, crow)[j];
                tcut[td] = tcut[td] - (tcomp * s_amt[e] + comp * ts_amt[te]);
                tcut_rate[td] = tcut_rate[td] - (tcomp * s_pred[e] + comp * ts_pred[te]);
              }
            }
          }
      }
      // body 0: half kick, friction, drift, predicted velocity
      for (int64_t j = 0; j < kLanes; ++j) {
        double w = v[j] + h * a[j];
        if constexpr (kBooks) {
          raw_prev[j] = w;
          work1[j] = work2[j] = lost1[j] = lost2[j] = d_prev[j] = 0.0;
        }
        if (kFriction) {
          if constexpr (kTangent)
            w = kick_slopes(w, loss[j], &kick1_w[j], &kick1_loss[j]);
          else
            w = kick(w, loss[j]);
        }
        x[j] = x[j] + dt * w;
        w_prev[j] = w;
        p_prev[j] = w + h * a[j];
        f_prev[j] = 0.0;
      }
      if (kTangent)
        for (int64_t d = 0; d < D; ++d)
          ForLanes<kLanes>([&](int64_t j) HC_LANES {
            const int64_t q = d * kLanes + j;
            double tw = tv[d * rows_x * kLanes + j] + h * ta[d * rows_x * kLanes + j];
            if (kFriction) tw = kick1_w[j] * tw + kick1_loss[j] * tloss[q];
            tx[d * rows_x * kLanes + j] = tx[d * rows_x * kLanes + j] + dt * tw;
            tw_prev[q] = tw;
            tp_prev[q] = tw + h * ta[d * rows_x * kLanes + j];
            tf_prev[q] = 0.0;
          });
      for (int64_t i = 0; i < contacts; ++i) {
        const int64_t ri = i * kLanes, rn = (i + 1) * kLanes;
        // kSensors: the sensor whose back (sb) and front (sf_) contact this is (-1: none)
        const int64_t sb = kSensors ? back_of[i] : -1, sf_ = kSensors ? front_of[i] : -1;
        // kUK / kUM: kappa and 1.5 eta kappa / the inverse mass of body i are one value
        // for every lane of the row (read once: the same numbers)
        auto sweep = [&](auto uniform_k_tag, auto uniform_m_tag, auto own_tag) HC_LANES {
        constexpr bool kUK = decltype(uniform_k_tag)::value, kUM = decltype(uniform_m_tag)::value;
        constexpr bool kOwn = decltype(own_tag)::value;
        const double k0 = kap[ri], kv0 = kvis[ri], d0 = kDashpot ? dsh[ri] : 0.0, m0 = inv[ri];
        ForLanes<kLanes>([&](int64_t j) HC_LANES {
          const double kj = kUK ? k0 : kap[ri + j], kvj = kUK ? kv0 : kvis[ri + j];
          const double dj = kDashpot ? (kUK ? d0 : dsh[ri + j]) : 0.0;
          // body i + 1: half kick, friction, drift, predicted velocity
          double w = v[rn + j] + h * a[rn + j];
          double w_raw = w;
          if (kFriction) {
            if constexpr (kTangent)
              w = kick_slopes(w, loss[j], &kick1_w[j], &kick1_loss[j]);
            else
              w = kick(w, loss[j]);
          }
          x[rn + j] = x[rn + j] + dt * w;
          double pred = w + h * a[rn + j];
          // contact i
          double dl = x[ri + j] - x[rn + j];
          if constexpr (kExtras) dl = dl + ov0[ri + j];
          double rt_rate = p_prev[j] - pred;
          if constexpr (kSensors) {
            dl = dl + cut[ri + j];
            rt_rate = rt_rate + cut_rate[ri + j];
          }
          double elastic_i;
          double f;
          if constexpr (kTangent)
            f = contact_slopes(own_tag, dl, rt_rate, kj, c1[j], dash[j], spr[ri + j], ri + j, j, &force_slopes[j],
                               kLanes);
          else
            f = law_force(dl, rt_rate, kj, kvj, dj, spr[ri + j], law_in(ri + j, j, 0), law_in(ri + j, j, 1),
                          kBooks ? &elastic_i : nullptr);
          // body i: second half kick, friction
          double b = f_prev[j] - f;
          if constexpr (kExtras) b = b + ext[ri + j];
          double acc = b * (kUM ? m0 : inv[ri + j]);
          double vn = w_prev[j] + h * acc;
          double vn_raw = vn;
          if (kFriction) {
            if constexpr (kTangent)
              vn = kick_slopes(vn, loss[j], &kick2_w[j], &kick2_loss[j]);
            else
              vn = kick(vn, loss[j]);
          }
          if constexpr (kBooks) {  // body i's energy terms, contact i's largest force
            if (kViscous) {
              // total - elastic of contact i (springs in both, as `batched` adds them)
              double elastic = elastic_i;
              if constexpr (kExtras) elastic = elastic + spr[ri + j] * dl;
              const double di = f - elastic, viscous = d_prev[j] - di;
              work1[j] = work1[j] + vis[ri + j] * h * 0.5 * (v[ri + j] + raw_prev[j]);
              work2[j] = work2[j] + viscous * h * 0.5 * (w_prev[j] + vn_raw);
              vis[ri + j] = viscous;
              d_prev[j] = di;
            }
            if (kFriction) {
              lost1[j] = lost1[j] + mass[ri + j] * (raw_prev[j] * raw_prev[j] - w_prev[j] * w_prev[j]);
              lost2[j] = lost2[j] + mass[ri + j] * (vn_raw * vn_raw - vn * vn);
            }
            top[ri + j] = std::max(top[ri + j], f);
            raw_prev[j] = w_raw;
          }
          a[ri + j] = acc;
          v[ri + j] = vn;
          if constexpr (kTangent && kOwn) body[j] = b;  // what the tangent pass needs of this step
          f_prev[j] = f;
          w_prev[j] = w;
          p_prev[j] = pred;
        });
        };
        if constexpr (kPlastic) {
          // Contact i's largest overlap so far, with this step's (`batched._step`), before the
          // sweep: the overlap from body i + 1's drift as the sweep computes it (the same
          // operations, so the same bits), then the unloading curve of the lanes whose
          // overlap grew. The sweep itself then has no branch and vectorises.
          bool grown = false;
          ForLanes<kLanes>([&](int64_t j) HC_LANES {
            double w = v[rn + j] + h * a[rn + j];
            if (kFriction) w = kick(w, loss[j]);
            double dl = x[ri + j] - (x[rn + j] + dt * w);
            if constexpr (kExtras) dl = dl + ov0[ri + j];
            if constexpr (kSensors) dl = dl + cut[ri + j];
            const double old = pk[ri + j];
            if constexpr (kTangent) {
              const auto peak = hertzchain::Max(hertzchain::Seed<2, 0>(old), hertzchain::Seed<2, 1>(dl));
              peak_by_old[j] = hertzchain::Slope(peak, 0);
              peak_by_overlap[j] = hertzchain::Slope(peak, 1);
            }
            fresh[j] = dl > old && yields[ri + j] != 0.0 ? 1.0 : 0.0;
            pk[ri + j] = hertzchain::Max(old, dl);
            grown = grown || fresh[j] != 0.0;
          });
          if (grown)
            for (int64_t j = 0; j < kLanes; ++j)
              if (fresh[j] != 0.0) unload(i, j);
        }
        using T = std::true_type;
        using F = std::false_type;
        auto sweep_own = [&](auto own) HC_LANES {
          if (uniform_k[i]) {
            uniform_m[i] ? sweep(T{}, T{}, own) : sweep(T{}, F{}, own);
          } else {
            uniform_m[i] ? sweep(F{}, T{}, own) : sweep(F{}, F{}, own);
          }
        };
        if constexpr (kTangent) {
          fixed_inputs ? sweep_own(F{}) : sweep_own(T{});
        } else {
          sweep_own(T{});
        }
        if constexpr (kSensors) {  // contact i's total force: a sensor's next drive
          if (sb >= 0) std::copy(f_prev, f_prev + kLanes, &s_fb[sb * kLanes]);
          if (sf_ >= 0) std::copy(f_prev, f_prev + kLanes, &s_ff[sf_ * kLanes]);
        }
        // the tangent pass; kFixed: the bodies' and contacts' own inputs (inverse masses,
        // kappa, preload, springs, external forces) have no tangent in this block (`fixed_inputs`)
        auto tangent_pass = [&](auto fixed_tag) HC_LANES {
          constexpr bool kFixed = decltype(fixed_tag)::value;
          for (int64_t d = 0; d < D; ++d) {
            const int64_t ti = (d * rows_x + i) * kLanes, tn = (d * rows_x + i + 1) * kLanes;
            const int64_t tc = (d * contacts + i) * kLanes;
            ForLanes<kLanes>([&](int64_t j) HC_LANES {
              const int64_t q = d * kLanes + j;
              double tw = tv[tn + j] + h * ta[tn + j];
              if (kFriction) tw = kick1_w[j] * tw + kick1_loss[j] * tloss[q];
              tx[tn + j] = tx[tn + j] + dt * tw;
              double tpred = tw + h * ta[tn + j];
              double tdl = tx[ti + j] - tx[tn + j];
              if constexpr (kExtras && !kFixed) tdl = tdl + tov0[tc + j];
              double trate = tp_prev[q] - tpred;
              if constexpr (kSensors) {
                tdl = tdl + tcut[tc + j];
                trate = trate + tcut_rate[tc + j];
              }
              if constexpr (kPlastic)  // the peak's tangent: max(peak, overlap)'s
                tpk[tc + j] = peak_by_old[j] * tpk[tc + j] + peak_by_overlap[j] * tdl;
              double tlaw0, tlaw1;
              law_tangents(i, j, d, &tlaw0, &tlaw1);
              double tf = force_tangent(std::bool_constant<!kFixed>{}, &force_slopes[j], kLanes, tdl, trate,
                                        tkap[tc + j], t15eta[q], tdash[q], kFixed ? 0.0 : tspr[tc + j], tlaw0, tlaw1);
              double tb = tf_prev[q] - tf;
              if constexpr (kExtras && !kFixed) tb = tb + text[ti + j];
              double tacc = tb * inv[ri + j];
              if constexpr (!kFixed) tacc = tacc + body[j] * tinv[ti + j];
              double tvn = tw_prev[q] + h * tacc;
              if (kFriction) tvn = kick2_w[j] * tvn + kick2_loss[j] * tloss[q];
              ta[ti + j] = tacc;
              tv[ti + j] = tvn;
              tf_prev[q] = tf;
              tw_prev[q] = tw;
              tp_prev[q] = tpred;
            });
            if constexpr (kSensors) {
              const double* tf_i = &tf_prev[d * kLanes];
              if (sb >= 0) std::copy(tf_i, tf_i + kLanes, &ts_fb[(d * ns + sb) * kLanes]);
              if (sf_ >= 0) std::copy(tf_i, tf_i + kLanes, &ts_ff[(d * ns + sf_) * kLanes]);
            }
          }
        };
        if constexpr (kTangent) fixed_inputs ? tangent_pass(T{}) : tangent_pass(F{});
      }
      // the wall's row (inverse mass 0: it stays at rest, as in the JAX kernel)
      const int64_t rw = contacts * kLanes;
      for (int64_t j = 0; j < kLanes; ++j) {
        double b = f_prev[j];
        if constexpr (kExtras) b = b + ext[rw + j];
        double acc = b * inv[rw + j];
        double vn = w_prev[j] + h * acc;
        const double vn_raw = vn;
        if (kFriction) {
          if constexpr (kTangent)
            vn = kick_slopes(vn, loss[j], &kick2_w[j], &kick2_loss[j]);
          else
            vn = kick(vn, loss[j]);
        }
        if constexpr (kBooks) {  // the wall's terms, then the step's dissipation
          if (kViscous) {
            work1[j] = work1[j] + vis[rw + j] * h * 0.5 * (v[rw + j] + raw_prev[j]);
            work2[j] = work2[j] + d_prev[j] * h * 0.5 * (w_prev[j] + vn_raw);
            vis[rw + j] = d_prev[j];
          }
          const double work = damped[j] != 0.0 ? work1[j] + work2[j] : 0.0;
          spent[j] = (spent[j] - work) + (0.5 * lost1[j] + 0.5 * lost2[j]);
        }
        body[j] = b;
        a[rw + j] = acc;
        v[rw + j] = vn;
      }
      if (kTangent)
        for (int64_t d = 0; d < D; ++d)
          ForLanes<kLanes>([&](int64_t j) HC_LANES {
            const int64_t q = d * kLanes + j, tw_row = (d * rows_x + contacts) * kLanes;
            double tb = tf_prev[q];
            if constexpr (kExtras) tb = tb + text[tw_row + j];
            double tacc = tb * inv[rw + j] + body[j] * tinv[tw_row + j];
            double tvn = tw_prev[q] + h * tacc;
            if (kFriction) tvn = kick2_w[j] * tvn + kick2_loss[j] * tloss[q];
            ta[tw_row + j] = tacc;
            tv[tw_row + j] = tvn;
          });
      if constexpr (kSensors) {  // the sensors' second half kick, from the new drive (`compliant_sensor.kick`)
        for (int64_t k = 0; k < ns; ++k)
          for (int64_t j = 0; j < kLanes; ++j) {
            const int64_t c = k * kLanes + j;
            const double beta = sp[beta_row(k) * kLanes + j], inv_w2 = sp[inv_row(k) * kLanes + j];
            const bool quasi = s_quasi[c] != 0.0;
            const double drive = beta * s_fb[c] + (1.0 - beta) * s_ff[c];
            const double gap = drive - sf[c];
            const double accel = quasi ? 0.0 : gap / inv_w2;
            if constexpr (kTangent)
              for (int64_t d = 0; d < D; ++d) {
                const int64_t q = (d * ns + k) * kLanes + j;
                const double tbeta = tsens(d, beta_row(k))[j], tinv_w2 = tsens(d, inv_row(k))[j];
                const double tdrive =
                    (tbeta * s_fb[c] + beta * ts_fb[q]) + ((-tbeta) * s_ff[c] + (1.0 - beta) * ts_ff[q]);
                const double taccel =
                    quasi ? 0.0 : (tdrive - tsf[q]) / inv_w2 + ((-tinv_w2) * gap) * (1.0 / (inv_w2 * inv_w2));
                tsr[q] = quasi ? 0.0 : ts_half[q] + h * taccel;
                tsd[q] = tdrive;
              }
            sr[c] = quasi ? 0.0 : s_half[c] + h * accel;
            sd[c] = drive;
          }
      }
    }
    // The recorded channels from the new displacements and velocities.
    for (int64_t c = 0; c < n_channels; ++c) {
      const int64_t i = channels[c], ri = i * kLanes, rn = (i + 1) * kLanes;
      // kSensors: the sensors' forces and rates at the sample shorten contact i
      const int64_t sb = kSensors ? back_of[i] : -1, sf_ = kSensors ? front_of[i] : -1;
      for (int64_t j = 0; j < kLanes; ++j) {
        double dl = x[ri + j] - x[rn + j];
        if constexpr (kExtras) dl = dl + ov0[ri + j];
        double rate = v[ri + j] - v[rn + j];
        if constexpr (kSensors) {
          const double first = sp[first_row * kLanes + j];
          if (sb >= 0) {
            dl = dl - sp[back_row(sb) * kLanes + j] * (sf[sb * kLanes + j] - first);
            rate = rate - sp[back_row(sb) * kLanes + j] * sr[sb * kLanes + j];
          }
          if (sf_ >= 0) {
            dl = dl - sp[front_row(sf_) * kLanes + j] * (sf[sf_ * kLanes + j] - first);
            rate = rate - sp[front_row(sf_) * kLanes + j] * sr[sf_ * kLanes + j];
          }
        }
        if constexpr (!kTangent) {
          const double dj = kDashpot ? dsh[ri + j] : 0.0;
          record.slot(0, c)[j] = law_force(dl, rate, kap[ri + j], kvis[ri + j], dj, spr[ri + j], law_in(ri + j, j, 0),
                                           law_in(ri + j, j, 1), nullptr);
          continue;
        }
        double here[kForceInputs];  // the force's partials (`contact_slopes`)
        record.slot(0, c)[j] =
            contact_slopes(std::true_type{}, dl, rate, kap[ri + j], c1[j], dash[j], spr[ri + j], ri + j, j, here, 1);
        for (int64_t d = 0; d < D; ++d) {
          const int64_t q = d * kLanes + j;
          const int64_t ti = (d * rows_x + i) * kLanes, tn = (d * rows_x + i + 1) * kLanes;
          const int64_t tc = (d * contacts + i) * kLanes;
          double tdl = tx[ti + j] - tx[tn + j];
          if constexpr (kExtras) tdl = tdl + tov0[tc + j];
          double trate = tv[ti + j] - tv[tn + j];
          if constexpr (kSensors) {
            const double first = sp[first_row * kLanes + j], tfirst = tsens(d, first_row)[j];
            auto shorten = [&](int64_t k, int64_t row) {  // sensor k's compliance in `row`
              const double comp = sp[row * kLanes + j], tcomp = tsens(d, row)[j];
              const int64_t e = k * kLanes + j, te = (d * ns + k) * kLanes + j;
              tdl = tdl - (tcomp * (sf[e] - first) + comp * (tsf[te] - tfirst));
              trate = trate - (tcomp * sr[e] + comp * tsr[te]);
            };
            if (sb >= 0) shorten(sb, back_row(sb));
            if (sf_ >= 0) shorten(sf_, front_row(sf_));
          }
          double tlaw0, tlaw1;
          law_tangents(i, j, d, &tlaw0, &tlaw1);
          record.slot(d + 1, c)[j] = force_tangent(std::true_type{}, here, 1, tdl, trate, tkap[tc + j], t15eta[q],
                                                   tdash[q], tspr[tc + j], tlaw0, tlaw1);
        }
      }
    }
    record.advance(out);
  }
  if (record.buffered) record.flush(out);
  if constexpr (kBooks) {  // the packed state at the end, the block's own chains
    auto store = [&](const std::vector<double>& block, int64_t rows, int64_t row) {
      for (int64_t r = 0; r < rows; ++r)
        for (int64_t j = 0; j < valid; ++j) books.state[(row + r) * batch + lo + j] = block[r * kLanes + j];
    };
    store(x, rows_x, 0);
    store(v, rows_x, rows_x);
    store(a, rows_x, 2 * rows_x);
    if (kPlastic) store(pk, contacts, peak_row);
    store(top, contacts, top_row);
    if (kViscous) store(vis, rows_x, vis_row);
    store(spent, 1, spent_row);
  }
}

#if !defined(HC_DASHPOT_LIBRARY) && !defined(HC_LAW_LIBRARY) && !defined(HC_SENSOR_LIBRARY) && \
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

// The law of this library's runs: the power-law library's `contact.power_law_force`, the
// elastic-plastic libraries' `contact.thornton_contact` and `contact.jackson_green_contact`,
// the others Hertz's.
#if defined(HC_POWER_LIBRARY)
constexpr Law kLibraryLaw = Law::kPower;
#elif defined(HC_THORNTON_LIBRARY)
constexpr Law kLibraryLaw = Law::kThornton;
#elif defined(HC_JACKSON_GREEN_LIBRARY)
constexpr Law kLibraryLaw = Law::kJacksonGreen;
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
  // block widths to the library's build, not four; the laws other than Hertz's and the
  // compliant sensors in blocks of one width (`kOneWidth`)
  std::vector<Block> blocks;
  int64_t lo = 0;
  if constexpr (kOneWidth)
    for (; lo < batch; lo += kOneWidthLanes) blocks.push_back({lo, kOneWidthLanes});
  for (; lo + kWideLanes <= batch; lo += kWideLanes) blocks.push_back({lo, kWideLanes});
  constexpr bool kB = kPass == Pass::kBooks;
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
#if defined(HC_LAW_LIBRARY) || defined(HC_SENSOR_LIBRARY)
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

#if !defined(HC_DASHPOT_LIBRARY) && !defined(HC_LAW_LIBRARY) && !defined(HC_SENSOR_LIBRARY) && HC_PART_FORWARD
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
