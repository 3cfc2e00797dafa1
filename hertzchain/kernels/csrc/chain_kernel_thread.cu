// One thread per chain: the fused kernels of `chain_kernel.cc` for a GPU (CUDA), the whole
// trajectory of a chain in one launch with its state in registers. The chain's length is a
// compile-time constant (HC_ROWS = bodies + 1, the wall's row last), so that the loops over
// its contacts unroll and x, u (or x, v, a) and the tangents stay in registers; `native`
// builds one library per chain length and keeps it in its cache.
//
// The same source compiles for the host with HC_HOST_EMULATION (one loop over the threads,
// XLA's CPU platform): `tests/test_native.py` holds its numbers to the JAX kernel's where no
// GPU is present, and the GPU build to them where one is.
//
// The arithmetic is that of the JAX kernel and of `chain_kernel.cc`, operation for operation
// and in the same order (built without contraction into fused multiply-adds), and the laws
// are `chain_laws.h`'s, shared with `chain_kernel.cc`. Layouts (row-major, B chains on the
// fast axis, as in `batched`):
//   conservative: state0, state (R, B): x (HC_ROWS), u = v + (dt/2) a (HC_ROWS), and with
//     the books the largest overlap of every contact so far (HC_ROWS - 1 rows);
//   full: state0 (3 HC_ROWS, B): x, v, a; eta, friction (mu g), dashpot (1, 1 or B);
//   parameters (rows, 1 or B), tangents (D or 1, rows, B) (1: shared by every direction);
//   traces: one (n_samples, B) per channel, sample-major so that neighbouring threads write
//     neighbouring addresses (`native` transposes them), then (tangents) one
//     (D, n_samples, B) per channel. Thread t runs chain t % B along direction t / B; the
//     direction-0 threads write the forces.
#include <cstdint>
#include <type_traits>

#ifdef HC_HOST_EMULATION
#define HC_HD
#define HC_GLOBAL
#else
#include <cuda_runtime_api.h>
#define HC_HD __host__ __device__
#define HC_GLOBAL __global__
#endif

#include "xla/ffi/api/ffi.h"

#include "chain_ffi.h"
#include "chain_laws.h"
#include "chain_verlet.h"

namespace ffi = xla::ffi;

#ifndef HC_ROWS
#error "HC_ROWS (bodies + 1) must be defined"
#endif

namespace {

constexpr int kRows = HC_ROWS;
constexpr int kContacts = kRows - 1;
constexpr int kMaxChannels = 16;
#ifndef HC_THREADS_PER_BLOCK
#define HC_THREADS_PER_BLOCK 128  // (a build variant can set it: benchmarks/gpu_variants.py)
#endif
#ifndef HC_MIN_BLOCKS_PER_SM
#define HC_MIN_BLOCKS_PER_SM 1  // more caps the registers a thread (a build variant, likewise)
#endif
constexpr int kThreadsPerBlock = HC_THREADS_PER_BLOCK;

struct Param {
  const double* data;
  int64_t width;  // 1 (shared by the batch) or B
  HC_HD double at(int row, int64_t chain) const {
    return width == 1 ? data[row] : data[row * width + chain];
  }
};

struct Tangent {
  const double* data;
  bool shared;  // one direction for all
  HC_HD double at(int64_t direction, int row, int64_t rows, int64_t batch, int64_t chain) const {
    return data[(shared ? 0 : direction * rows * batch) + row * batch + chain];
  }
};

// The recorded contacts, one per output, and a bit per contact (set: recorded).
struct Channels {
  uint64_t mask[(kContacts + 63) / 64];
  int contact[kMaxChannels];
  int count;
  HC_HD bool recorded(int i) const { return (mask[i / 64] >> (i % 64)) & 1u; }
};

// f(std::integral_constant<int, k>) at the contact k == i (0 <= i < kContacts), found by a
// binary search over compile-time indices: the chain's state stays in registers (no index
// known only at run time), and a recorded channel costs log2(contacts) branches, the same
// in every thread.
template <int kLo, int kHi, class F>
HC_HD inline auto AtContact(int i, const F& f) {
  if constexpr (kHi - kLo == 1) {
    return f(std::integral_constant<int, kLo>{});
  } else {
    constexpr int kMid = (kLo + kHi) / 2;
    if (i < kMid) return AtContact<kLo, kMid>(i, f);
    return AtContact<kMid, kHi>(i, f);
  }
}


struct Outputs {
  double* trace[kMaxChannels];
  double* tangent[kMaxChannels];
};

struct ForwardArgs {
  int64_t batch, n_samples, steps_per_sample;
  double dt;
  const double* state0;
  Param inv_mass, kappa, overlap0, spring, external;
  Channels channels;
  double* state;
  Outputs out;
};

template <bool kPreload, bool kSprings, bool kBooks>
HC_HD void ForwardChain(const ForwardArgs& A, int64_t b) {
  const int64_t B = A.batch;
  const double dt = A.dt, h = 0.5 * dt;
  double x[kRows], u[kRows], mx[kBooks ? kContacts : 1];
#pragma unroll
  for (int r = 0; r < kRows; ++r) {
    x[r] = A.state0[r * B + b];
    u[r] = A.state0[(kRows + r) * B + b];
  }
  if (kBooks) {
#pragma unroll
    for (int i = 0; i < kContacts; ++i) mx[i] = A.state0[(2 * kRows + i) * B + b];
  }
  // the stiffnesses and inverse masses, read once (a sweep over walls gives every chain its
  // own stiffnesses; read at every step, the sweep of `benchmarks/gpu_kernel.py` ran 10 %
  // slower on an H100)
  double kappa[kContacts], inv_mass[kRows];
#pragma unroll
  for (int i = 0; i < kContacts; ++i) kappa[i] = A.kappa.at(i, b);
#pragma unroll
  for (int r = 0; r < kRows; ++r) inv_mass[r] = A.inv_mass.at(r, b);
  for (int64_t n = 0; n < A.n_samples; ++n) {
    for (int64_t s = 0; s < A.steps_per_sample; ++s) {
      // the striker's drift, then body by body the next body's drift, the force of the
      // contact between them and this body's full kick (`chain_verlet.h`)
      x[0] = x[0] + dt * u[0];
      double force_before = 0.0;
#pragma unroll
      for (int i = 0; i < kContacts; ++i) {
        double unused_top = 0.0;
        force_before = hertzchain::ConservativeContact<kPreload, kSprings, kBooks>(
            dt, h, x[i], x[i + 1], u[i + 1], u[i], kappa[i], kPreload ? A.overlap0.at(i, b) : 0.0,
            kSprings ? A.spring.at(i, b) : 0.0, inv_mass[i], kPreload ? A.external.at(i, b) : 0.0,
            kBooks ? mx[i] : unused_top, force_before);
      }
      // the wall's row (inverse mass 0: at rest)
      hertzchain::ConservativeWall<kPreload>(h, u[kContacts], inv_mass[kContacts],
                                             kPreload ? A.external.at(kContacts, b) : 0.0, force_before);
    }
    for (int c = 0; c < A.channels.count; ++c) {
      A.out.trace[c][n * B + b] = AtContact<0, kContacts>(A.channels.contact[c], [&](auto contact) {
        constexpr int i = decltype(contact)::value;
        double overlap = x[i] - x[i + 1];
        if (kPreload) overlap = overlap + A.overlap0.at(i, b);
        return hertzchain::ElasticForce<kSprings>(overlap, kappa[i], kSprings ? A.spring.at(i, b) : 0.0);
      });
    }
  }
#pragma unroll
  for (int r = 0; r < kRows; ++r) {
    A.state[r * B + b] = x[r];
    A.state[(kRows + r) * B + b] = u[r];
  }
  if (kBooks) {
#pragma unroll
    for (int i = 0; i < kContacts; ++i) A.state[(2 * kRows + i) * B + b] = mx[i];
  }
}

struct FullArgs {
  int64_t batch, n_samples, steps_per_sample, directions;
  double dt;
  const double* state0;
  Param inv_mass, kappa, overlap0, spring, external, eta, friction, dashpot;
  Tangent t_state0, t_inv_mass, t_kappa, t_overlap0, t_spring, t_external, t_eta, t_friction, t_dashpot;
  Channels channels;
  Outputs out;
};

// The full step of `chain_kernel.cc`'s RunFullBlock for one chain: Kuwabara-Kono damping and
// a linear dashpot (the total force clipped at 0), track friction before the drift and
// after the second half kick, the preload's and springs' terms (kExtras). One step over the
// number type T: doubles for the values, and (kTangent) dual numbers along the thread's
// tangent direction `d` (`hertzchain::Along`), so that the tangent is this same step run on
// them, the derivative rules JAX's jvp applies operation by operation (the values are the
// doubles' operations, so the same bits).
template <bool kViscous, bool kFriction, bool kTangent, bool kExtras, bool kDashpot>
HC_HD void FullChain(const FullArgs& A, int64_t b, int64_t d) {
  using namespace hertzchain;
  using T = std::conditional_t<kTangent, Dual<1, 1u>, double>;
  const int64_t B = A.batch;
  const double dt = A.dt, h = 0.5 * dt;
  // input `row` of (rows) of a parameter, with its tangent along the direction
  auto in = [&](const Param& p, const Tangent& t, int row, int rows) -> T {
    if constexpr (kTangent) {
      return Along(p.at(row, b), t.at(d, row, rows, B, b));
    } else {
      return p.at(row, b);
    }
  };
  auto state0 = [&](int row) -> T {
    if constexpr (kTangent) {
      return Along(A.state0[row * B + b], A.t_state0.at(d, row, 3 * kRows, B, b));
    } else {
      return A.state0[row * B + b];
    }
  };
  T x[kRows], v[kRows], a[kRows];
#pragma unroll
  for (int r = 0; r < kRows; ++r) {
    x[r] = state0(r);
    v[r] = state0(kRows + r);
    a[r] = state0(2 * kRows + r);
  }
  const T eta = in(A.eta, A.t_eta, 0, 1), loss = in(A.friction, A.t_friction, 0, 1) * h, c1 = 1.5 * eta;
  const T dashpot = kDashpot ? in(A.dashpot, A.t_dashpot, 0, 1) : Like(eta, 0.0);
  // contact i's total force at overlap dl and rate
  auto force = [&](int i, const T& dl, const T& rate) {
    const T k = in(A.kappa, A.t_kappa, i, kContacts);
    const T sp = kExtras ? in(A.spring, A.t_spring, i, kContacts) : Like(eta, 0.0);
    return TotalForce<kViscous, kExtras, kDashpot>(dl, rate, k, c1 * k, ContactDashpot(k, dashpot), sp);
  };
  // the friction kick (`chain_verlet.h`'s phases take it)
  auto friction = [&](const T& w) -> T {
    if constexpr (kFriction) {
      return Kick(w, loss);
    } else {
      return w;
    }
  };
  // the second half kick of body i by the force `body` on it, and friction
  auto kick = [&](int i, const T& body, const T& w) {
    const T acc = body * in(A.inv_mass, A.t_inv_mass, i, kRows);
    v[i] = SecondHalfKick(w, acc, h, friction);
    a[i] = acc;
  };

  for (int64_t n = 0; n < A.n_samples; ++n) {
    for (int64_t s = 0; s < A.steps_per_sample; ++s) {
      // body 0: half kick, friction, drift, predicted velocity
      T p_prev;
      T w_prev = HalfKickAndDrift(v[0], a[0], h, dt, friction, x[0], p_prev), f_prev = Like(eta, 0.0);
#pragma unroll
      for (int i = 0; i < kContacts; ++i) {
        const int nx = i + 1;
        // body i + 1: half kick, friction, drift, predicted velocity
        T pred;
        const T wn = HalfKickAndDrift(v[nx], a[nx], h, dt, friction, x[nx], pred);
        // contact i
        T dl = x[i] - x[nx];
        if (kExtras) dl = dl + in(A.overlap0, A.t_overlap0, i, kContacts);
        const T f = force(i, dl, p_prev - pred);
        // body i: second half kick, friction
        T body = f_prev - f;
        if (kExtras) body = body + in(A.external, A.t_external, i, kRows);
        kick(i, body, w_prev);
        f_prev = f;
        w_prev = wn;
        p_prev = pred;
      }
      // the wall's row (inverse mass 0: at rest)
      T body = f_prev;
      if (kExtras) body = body + in(A.external, A.t_external, kContacts, kRows);
      kick(kContacts, body, w_prev);
    }
    // the recorded channels from the new displacements and velocities
    // (every contact tested in turn: a search as the conservative kernel's costs the
    // tangent runs their registers)
#pragma unroll
    for (int i = 0; i < kContacts; ++i) {
      if (!A.channels.recorded(i)) continue;
      T dl = x[i] - x[i + 1];
      if (kExtras) dl = dl + in(A.overlap0, A.t_overlap0, i, kContacts);
      const T f = force(i, dl, v[i] - v[i + 1]);
      for (int c = 0; c < A.channels.count; ++c) {
        if (A.channels.contact[c] != i) continue;
        if (d == 0) A.out.trace[c][n * B + b] = Value(f);
        if constexpr (kTangent) A.out.tangent[c][(d * A.n_samples + n) * B + b] = f.d[0];
      }
    }
  }
}

template <bool kP, bool kS, bool kB>
struct ForwardThread {
  ForwardArgs args;
  HC_HD void operator()(int64_t t) const { ForwardChain<kP, kS, kB>(args, t); }
};

template <bool kV, bool kF, bool kT, bool kE, bool kD>
struct FullThread {
  FullArgs args;
  HC_HD void operator()(int64_t t) const { FullChain<kV, kF, kT, kE, kD>(args, t % args.batch, t / args.batch); }
};

#ifdef HC_HOST_EMULATION
using Stream = int;  // no stream: the threads run one after another on the host
template <class Thread>
ffi::Error Launch(Stream, int64_t threads, const Thread& thread) {
  for (int64_t t = 0; t < threads; ++t) thread(t);
  return ffi::Error::Success();
}
#else
using Stream = cudaStream_t;
template <class Thread>
__global__ void __launch_bounds__(kThreadsPerBlock, HC_MIN_BLOCKS_PER_SM) Each(int64_t threads, Thread thread) {
  const int64_t t = static_cast<int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (t < threads) thread(t);
}
template <class Thread>
ffi::Error Launch(Stream stream, int64_t threads, const Thread& thread) {
  if (threads == 0) return ffi::Error::Success();
  const int64_t blocks = (threads + kThreadsPerBlock - 1) / kThreadsPerBlock;
  Each<<<static_cast<unsigned>(blocks), kThreadsPerBlock, 0, stream>>>(threads, thread);
  cudaError_t error = cudaGetLastError();
  if (error != cudaSuccess) return ffi::Error::Internal(cudaGetErrorString(error));
  return ffi::Error::Success();
}
#endif

Param AsParam(const ffi::Buffer<ffi::F64>& buffer) {
  auto dims = buffer.dimensions();
  return {buffer.typed_data(), dims.size() > 1 ? dims[dims.size() - 1] : 1};
}

// The recorded contacts, from the channel list (`contacts`, host memory: an attribute).
ffi::Error MakeChannels(ffi::Span<const int64_t> contacts, Channels* channels) {
  if (contacts.size() > static_cast<size_t>(kMaxChannels))
    return ffi::Error::InvalidArgument("at most 16 recorded channels per kernel run");
  *channels = Channels{};
  channels->count = static_cast<int>(contacts.size());
  for (int c = 0; c < channels->count; ++c) {
    const int64_t i = contacts[c];
    if (i < 0 || i >= kContacts) return ffi::Error::InvalidArgument("a recorded channel is not a contact");
    channels->contact[c] = static_cast<int>(i);
    channels->mask[i / 64] |= uint64_t{1} << (i % 64);
  }
  return ffi::Error::Success();
}

ffi::Error Forward(Stream stream, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                   ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> spring,
                   ffi::Buffer<ffi::F64> external, ffi::Span<const int64_t> contacts, double dt,
                   int64_t steps_per_sample, int64_t preload, int64_t springs, int64_t books,
                   ffi::ResultBuffer<ffi::F64> state, ffi::RemainingRets traces) {
  auto dims = state0.dimensions();
  if (dims.size() != 2) return ffi::Error::InvalidArgument("state0 must be (rows, B)");
  if (inv_mass.dimensions()[0] != kRows)
    return ffi::Error::InvalidArgument("the chain's length is not the one this kernel was built for");
  if (dims[0] != 2 * kRows + (books ? kContacts : 0))
    return ffi::Error::InvalidArgument("state0 rows do not match the bodies and books");
  ForwardArgs A{};
  if (auto error = MakeChannels(contacts, &A.channels); error.failure()) return error;
  A.batch = dims[1];
  A.steps_per_sample = steps_per_sample;
  A.dt = dt;
  A.state0 = state0.typed_data();
  A.inv_mass = AsParam(inv_mass);
  A.kappa = AsParam(kappa);
  A.overlap0 = AsParam(overlap0);
  A.spring = AsParam(spring);
  A.external = AsParam(external);
  A.state = state->typed_data();
  for (int c = 0; c < A.channels.count; ++c) {
    auto out = traces.get<ffi::Buffer<ffi::F64>>(c);
    if (out.has_error()) return out.error();
    A.n_samples = (*out)->dimensions()[0];
    A.out.trace[c] = (*out)->typed_data();
  }
  auto run = [&](auto p, auto s, auto k) {
    return Launch(stream, A.batch, ForwardThread<decltype(p)::value, decltype(s)::value, decltype(k)::value>{A});
  };
  using T = std::true_type;
  using F = std::false_type;
  auto with_books = [&](auto p, auto s) { return books ? run(p, s, T{}) : run(p, s, F{}); };
  auto with_springs = [&](auto p) { return springs ? with_books(p, T{}) : with_books(p, F{}); };
  return preload ? with_springs(T{}) : with_springs(F{});
}

int64_t Directions(const ffi::Buffer<ffi::F64>& buffer, int64_t rows, int64_t batch) {
  return static_cast<int64_t>(buffer.element_count()) / (rows * batch);
}

ffi::Error RunFull(Stream stream, FullArgs A, ffi::Buffer<ffi::F64> state0, ffi::Span<const int64_t> contacts,
                   bool tangent, int64_t viscous, int64_t friction_on, int64_t extras, int64_t dashpot_on,
                   ffi::RemainingRets results) {
  auto dims = state0.dimensions();
  A.batch = dims[dims.size() - 1];
  if (static_cast<int64_t>(state0.element_count()) != 3 * kRows * A.batch)
    return ffi::Error::InvalidArgument("state0 must be (3 rows, B) for this chain length");
  if (auto error = MakeChannels(contacts, &A.channels); error.failure()) return error;
  A.state0 = state0.typed_data();
  for (int c = 0; c < (tangent ? 2 : 1) * A.channels.count; ++c) {
    auto out = results.get<ffi::Buffer<ffi::F64>>(c);
    if (out.has_error()) return out.error();
    auto out_dims = (*out)->dimensions();
    A.n_samples = out_dims[out_dims.size() - 2];
    if (c < A.channels.count) A.out.trace[c] = (*out)->typed_data();
    else A.out.tangent[c - A.channels.count] = (*out)->typed_data();
  }
  const int64_t threads = A.batch * (tangent ? A.directions : 1);
  auto run = [&](auto v, auto f, auto t, auto e, auto d) {
    return Launch(stream, threads,
                  FullThread<decltype(v)::value, decltype(f)::value, decltype(t)::value, decltype(e)::value,
                             decltype(d)::value>{A});
  };
  using T = std::true_type;
  using F = std::false_type;
  // the tangents always with the preload's and springs' terms (zeros where there are none);
  // a dashpot (compiled in for its runs only, with the damping) likewise
  auto with_tangent = [&](auto v, auto f, auto d) {
    if (tangent) return run(v, f, T{}, T{}, d);
    if constexpr (decltype(d)::value) {
      return run(v, f, F{}, T{}, d);
    } else {
      return extras ? run(v, f, F{}, T{}, d) : run(v, f, F{}, F{}, d);
    }
  };
  auto with_friction = [&](auto v, auto d) {
    return friction_on ? with_tangent(v, T{}, d) : with_tangent(v, F{}, d);
  };
  if (dashpot_on && !viscous) return ffi::Error::InvalidArgument("a dashpot needs the viscous kernel");
  if (!viscous) return with_friction(F{}, F{});
  return dashpot_on ? with_friction(T{}, T{}) : with_friction(T{}, F{});
}

FullArgs FullParameters(double dt, int64_t steps_per_sample, ffi::Buffer<ffi::F64> inv_mass,
                        ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> spring,
                        ffi::Buffer<ffi::F64> external, ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction,
                        ffi::Buffer<ffi::F64> dashpot) {
  FullArgs A{};
  A.dt = dt;
  A.steps_per_sample = steps_per_sample;
  A.directions = 1;
  A.inv_mass = AsParam(inv_mass);
  A.kappa = AsParam(kappa);
  A.overlap0 = AsParam(overlap0);
  A.spring = AsParam(spring);
  A.external = AsParam(external);
  A.eta = AsParam(eta);
  A.friction = AsParam(friction);
  A.dashpot = AsParam(dashpot);
  return A;
}

ffi::Error FullForward(Stream stream, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                       ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> spring,
                       ffi::Buffer<ffi::F64> external, ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction,
                       ffi::Buffer<ffi::F64> dashpot, ffi::Span<const int64_t> contacts, double dt,
                       int64_t steps_per_sample, int64_t viscous, int64_t friction_on, int64_t extras,
                       int64_t dashpot_on, ffi::RemainingRets traces) {
  if (inv_mass.dimensions()[inv_mass.dimensions().size() - 2] != kRows)
    return ffi::Error::InvalidArgument("the chain's length is not the one this kernel was built for");
  FullArgs A = FullParameters(dt, steps_per_sample, inv_mass, kappa, overlap0, spring, external, eta, friction,
                              dashpot);
  return RunFull(stream, A, state0, contacts, false, viscous, friction_on, extras, dashpot_on, traces);
}

ffi::Error FullTangent(Stream stream, ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
                       ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> spring,
                       ffi::Buffer<ffi::F64> external, ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> friction,
                       ffi::Buffer<ffi::F64> dashpot, ffi::Buffer<ffi::F64> t_state0,
                       ffi::Buffer<ffi::F64> t_inv_mass, ffi::Buffer<ffi::F64> t_kappa,
                       ffi::Buffer<ffi::F64> t_overlap0, ffi::Buffer<ffi::F64> t_spring,
                       ffi::Buffer<ffi::F64> t_external, ffi::Buffer<ffi::F64> t_eta,
                       ffi::Buffer<ffi::F64> t_friction, ffi::Buffer<ffi::F64> t_dashpot,
                       ffi::Span<const int64_t> contacts, double dt, int64_t steps_per_sample, int64_t viscous,
                       int64_t friction_on, int64_t extras, int64_t dashpot_on, ffi::RemainingRets tangent_traces) {
  if (inv_mass.dimensions()[inv_mass.dimensions().size() - 2] != kRows)
    return ffi::Error::InvalidArgument("the chain's length is not the one this kernel was built for");
  auto dims = state0.dimensions();
  const int64_t batch = dims[dims.size() - 1];
  const int64_t counts[9] = {
      Directions(t_state0, 3 * kRows, batch), Directions(t_inv_mass, kRows, batch),
      Directions(t_kappa, kContacts, batch),  Directions(t_overlap0, kContacts, batch),
      Directions(t_spring, kContacts, batch), Directions(t_external, kRows, batch),
      Directions(t_eta, 1, batch),            Directions(t_friction, 1, batch),
      Directions(t_dashpot, 1, batch)};
  int64_t directions = 1;
  for (int64_t count : counts) directions = count > directions ? count : directions;
  for (int64_t count : counts)
    if (count != 1 && count != directions)
      return ffi::Error::InvalidArgument("tangents must be (directions or 1, rows, B)");
  FullArgs A = FullParameters(dt, steps_per_sample, inv_mass, kappa, overlap0, spring, external, eta, friction,
                              dashpot);
  A.directions = directions;
  auto tangent = [&](const ffi::Buffer<ffi::F64>& buffer, int64_t count) {
    return Tangent{buffer.typed_data(), count == 1};
  };
  A.t_state0 = tangent(t_state0, counts[0]);
  A.t_inv_mass = tangent(t_inv_mass, counts[1]);
  A.t_kappa = tangent(t_kappa, counts[2]);
  A.t_overlap0 = tangent(t_overlap0, counts[3]);
  A.t_spring = tangent(t_spring, counts[4]);
  A.t_external = tangent(t_external, counts[5]);
  A.t_eta = tangent(t_eta, counts[6]);
  A.t_friction = tangent(t_friction, counts[7]);
  A.t_dashpot = tangent(t_dashpot, counts[8]);
  return RunFull(stream, A, state0, contacts, true, viscous, friction_on, extras, dashpot_on, tangent_traces);
}

#ifdef HC_HOST_EMULATION
// No stream on the host: the handlers' first argument is a dummy.
ffi::Error ForwardHost(ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass, ffi::Buffer<ffi::F64> kappa,
                       ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> spring, ffi::Buffer<ffi::F64> external,
                       ffi::Span<const int64_t> contacts, double dt, int64_t steps_per_sample, int64_t preload,
                       int64_t springs, int64_t books, ffi::ResultBuffer<ffi::F64> state,
                       ffi::RemainingRets traces) {
  return Forward(0, state0, inv_mass, kappa, overlap0, spring, external, contacts, dt, steps_per_sample, preload,
                 springs, books, state, traces);
}
#define HC_FORWARD ForwardHost
#define HC_BIND ffi::Ffi::Bind()
#else
#define HC_FORWARD Forward
#define HC_BIND ffi::Ffi::Bind().Ctx<ffi::PlatformStream<cudaStream_t>>()
#endif

}  // namespace

#ifdef HC_HOST_EMULATION
namespace {
ffi::Error FullForwardHost(ffi::Buffer<ffi::F64> s, ffi::Buffer<ffi::F64> m, ffi::Buffer<ffi::F64> k,
                           ffi::Buffer<ffi::F64> o, ffi::Buffer<ffi::F64> sp, ffi::Buffer<ffi::F64> e,
                           ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> fr, ffi::Buffer<ffi::F64> ds,
                           ffi::Span<const int64_t> c, double dt, int64_t n, int64_t v, int64_t f, int64_t x,
                           int64_t dp, ffi::RemainingRets r) {
  return FullForward(0, s, m, k, o, sp, e, eta, fr, ds, c, dt, n, v, f, x, dp, r);
}
ffi::Error FullTangentHost(ffi::Buffer<ffi::F64> s, ffi::Buffer<ffi::F64> m, ffi::Buffer<ffi::F64> k,
                           ffi::Buffer<ffi::F64> o, ffi::Buffer<ffi::F64> sp, ffi::Buffer<ffi::F64> e,
                           ffi::Buffer<ffi::F64> eta, ffi::Buffer<ffi::F64> fr, ffi::Buffer<ffi::F64> ds,
                           ffi::Buffer<ffi::F64> ts, ffi::Buffer<ffi::F64> tm, ffi::Buffer<ffi::F64> tk,
                           ffi::Buffer<ffi::F64> to, ffi::Buffer<ffi::F64> tsp, ffi::Buffer<ffi::F64> te,
                           ffi::Buffer<ffi::F64> teta, ffi::Buffer<ffi::F64> tfr, ffi::Buffer<ffi::F64> tds,
                           ffi::Span<const int64_t> c, double dt, int64_t n, int64_t v, int64_t f, int64_t x,
                           int64_t dp, ffi::RemainingRets r) {
  return FullTangent(0, s, m, k, o, sp, e, eta, fr, ds, ts, tm, tk, to, tsp, te, teta, tfr, tds, c, dt, n, v, f, x,
                     dp, r);
}
}  // namespace
#define HC_FULL_FORWARD FullForwardHost
#define HC_FULL_TANGENT FullTangentHost
#else
#define HC_FULL_FORWARD FullForward
#define HC_FULL_TANGENT FullTangent
#endif

// The handlers' argument lists: `chain_ffi.h` (the recorded channels, an attribute here,
// before the others). Traces come back (n_samples, B).
XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainThreadForward, HC_FORWARD,
                              hertzchain::ForwardAttrs(hertzchain::ChainArgs(HC_BIND)
                                                           .Attr<ffi::Span<const int64_t>>("channels"))
                                  .Ret<ffi::Buffer<ffi::F64>>()  // state
                                  .RemainingRets());             // traces

XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainThreadFullForward, HC_FULL_FORWARD,
                              hertzchain::FullAttrs(hertzchain::FullArgs(HC_BIND)
                                                        .Attr<ffi::Span<const int64_t>>("channels"))
                                  .RemainingRets());  // traces

XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainThreadFullTangent, HC_FULL_TANGENT,
                              hertzchain::FullAttrs(hertzchain::FullArgs(hertzchain::FullArgs(HC_BIND))  // values, tangents
                                                        .Attr<ffi::Span<const int64_t>>("channels"))
                                  .RemainingRets());  // traces, then (D, n_samples, B)
