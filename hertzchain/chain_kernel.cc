// A fused multi-step kernel for `hertzchain.batched`: the conservative velocity-Verlet
// step of `batched._step` (Hertz contacts, linear sensor springs, static overlaps and
// external forces of a preload, a wall or a free end) for a block of chains at a time,
// all steps of the run while the block's state sits in the cache, every contact's force
// computed once per step and used for both bodies it pushes.
//
// The arithmetic is that of the JAX kernel, operation for operation and in the same
// order (compiled without contraction into fused multiply-adds), so that the two agree to
// round-off; `tests/test_native.py` checks it. Layouts (row-major, the chain on the fast
// axis, as in `batched`):
//   state0, state  (R, B): x (bodies + 1 rows, the wall last, at rest), u = v + (dt/2) a
//                          (bodies + 1), and with books the largest overlap of every
//                          contact so far (bodies rows).
//   inv_mass (bodies + 1, 1 or B), kappa / overlap0 / spring (bodies, 1 or B),
//   external (bodies + 1, 1 or B): a width of 1 is one value shared by every chain.
//   channels (n_channels,): the contacts whose force is recorded after every sample.
//   traces: n_channels results of (B, n_samples), N.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

// Chains advanced together (the vectorised axis): blocks of 64 (measured best on a 2-core
// AVX-512 EPYC against 16, 32 and 128: the block's state stays in L1/L2), the remainder of
// the batch in blocks of 8 (one AVX-512 vector) and the last few chains one at a time (a
// single chain in an 8-lane block ran at half the speed of the JAX kernel).
constexpr int64_t kWideLanes = 64;
constexpr int64_t kNarrowLanes = 8;
constexpr int64_t kSampleBuffer = 64;   // samples kept per chain before they are written out

struct Param {
  const double* data;
  int64_t width;  // 1 (shared by the batch) or B
};

// Rows of `p` for chains lo..lo+kLanes-1 into a (rows, kLanes) block.
template <int64_t kLanes>
void Load(Param p, int64_t rows, int64_t lo, double* block) {
  for (int64_t r = 0; r < rows; ++r)
    for (int64_t j = 0; j < kLanes; ++j)
      block[r * kLanes + j] = p.width == 1 ? p.data[r] : p.data[r * p.width + lo + j];
}

template <bool kSprings>
inline double ContactForce(double overlap, double kappa, double spring) {
  // contact.hertz_force: kappa * delta_+ * sqrt(delta_+), then + spring * delta
  double positive = overlap > 0.0 ? overlap : 0.0;
  double force = kappa * positive * std::sqrt(positive);
  if (kSprings) force = force + spring * overlap;
  return force;
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
  std::vector<double> record(n_channels * kLanes * kSampleBuffer);
  Load<kLanes>({state0, batch}, rows_x, lo, x.data());
  Load<kLanes>({state0 + rows_x * batch, batch}, rows_x, lo, u.data());
  if (kBooks) Load<kLanes>({state0 + 2 * rows_x * batch, batch}, contacts, lo, mx.data());
  Load<kLanes>(inv_mass, rows_x, lo, inv.data());
  Load<kLanes>(kappa, contacts, lo, kap.data());
  Load<kLanes>(overlap0, contacts, lo, ov0.data());
  Load<kLanes>(spring, contacts, lo, spr.data());
  Load<kLanes>(external, rows_x, lo, ext.data());

  double force_before[kLanes];
  int64_t buffered = 0, written = 0;
  auto flush = [&]() {
    for (int64_t c = 0; c < n_channels; ++c)
      for (int64_t j = 0; j < kLanes; ++j) {
        double* out = traces[c] + (lo + j) * n_samples + written;
        const double* in = &record[(c * kLanes + j) * kSampleBuffer];
        std::copy(in, in + buffered, out);
      }
    written += buffered;
    buffered = 0;
  };

  for (int64_t n = 0; n < n_samples; ++n) {
    for (int64_t s = 0; s < steps_per_sample; ++s) {
      // Drift of the striker, then, body by body, the drift of the next body, the force
      // of the contact between them and the full kick of this body (v = u + h a, then
      // u = v + h a, as the JAX kernel rounds them).
      for (int64_t j = 0; j < kLanes; ++j) {
        x[j] = x[j] + dt * u[j];
        force_before[j] = 0.0;
      }
      for (int64_t i = 0; i < contacts; ++i) {
        double* xi = &x[i * kLanes];
        double* xn = &x[(i + 1) * kLanes];
        const double* un = &u[(i + 1) * kLanes];
        double* ui = &u[i * kLanes];
        const double* k = &kap[i * kLanes];
        const double* o = &ov0[i * kLanes];
        const double* sp = &spr[i * kLanes];
        const double* m = &inv[i * kLanes];
        const double* e = &ext[i * kLanes];
        double* top = &mx[i * kLanes];
#pragma GCC ivdep
        for (int64_t j = 0; j < kLanes; ++j) {
          xn[j] = xn[j] + dt * un[j];
          double overlap = kPreload ? (xi[j] - xn[j]) + o[j] : xi[j] - xn[j];
          double force = ContactForce<kSprings>(overlap, k[j], sp[j]);
          if (kBooks) top[j] = std::max(top[j], overlap);
          double body = force_before[j] - force;
          if (kPreload) body = body + e[j];
          double a = body * m[j];
          double v = ui[j] + h * a;
          ui[j] = v + h * a;
          force_before[j] = force;
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
    // The recorded channels from the new displacements (as the JAX kernel records them).
    for (int64_t c = 0; c < n_channels; ++c) {
      int64_t i = channels[c];
      for (int64_t j = 0; j < kLanes; ++j) {
        double overlap = x[i * kLanes + j] - x[(i + 1) * kLanes + j];
        if (kPreload) overlap = overlap + ov0[i * kLanes + j];
        record[(c * kLanes + j) * kSampleBuffer + buffered] =
            ContactForce<kSprings>(overlap, kap[i * kLanes + j], spr[i * kLanes + j]);
      }
    }
    if (++buffered == kSampleBuffer) flush();
  }
  if (buffered) flush();

  auto store = [&](const std::vector<double>& block, int64_t rows, double* dst) {
    for (int64_t r = 0; r < rows; ++r)
      for (int64_t j = 0; j < kLanes; ++j) dst[r * batch + lo + j] = block[r * kLanes + j];
  };
  store(x, rows_x, state);
  store(u, rows_x, state + rows_x * batch);
  if (kBooks) store(mx, contacts, state + 2 * rows_x * batch);
}

Param AsParam(const ffi::Buffer<ffi::F64>& buffer) {
  auto dims = buffer.dimensions();
  return {buffer.typed_data(), dims.size() > 1 ? dims[dims.size() - 1] : 1};
}

ffi::Error Forward(ffi::Buffer<ffi::F64> state0, ffi::Buffer<ffi::F64> inv_mass,
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
    if (rows[c] < 0 || rows[c] >= bodies)
      return ffi::Error::InvalidArgument("a recorded channel is not a contact");
  }
  auto run = [&](auto preload_tag, auto springs_tag, auto books_tag) {
    constexpr bool kP = decltype(preload_tag)::value, kS = decltype(springs_tag)::value,
                   kB = decltype(books_tag)::value;
    int64_t lo = 0;
    auto advance = [&](auto lanes) {
      constexpr int64_t kL = decltype(lanes)::value;
      RunBlock<kL, kP, kS, kB>(bodies, lo, batch, n_samples, steps_per_sample, dt,
                               state0.typed_data(), AsParam(inv_mass), AsParam(kappa),
                               AsParam(overlap0), AsParam(spring), AsParam(external), rows,
                               state->typed_data(), outs);
      lo += kL;
    };
    while (lo + kWideLanes <= batch) advance(std::integral_constant<int64_t, kWideLanes>{});
    while (lo + kNarrowLanes <= batch) advance(std::integral_constant<int64_t, kNarrowLanes>{});
    while (lo < batch) advance(std::integral_constant<int64_t, 1>{});
  };
  using T = std::true_type;
  using F = std::false_type;
  auto with_books = [&](auto p, auto s) { books ? run(p, s, T{}) : run(p, s, F{}); };
  auto with_springs = [&](auto p) { springs ? with_books(p, T{}) : with_books(p, F{}); };
  preload ? with_springs(T{}) : with_springs(F{});
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainForward, Forward,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()  // state0
                                  .Arg<ffi::Buffer<ffi::F64>>()  // inv_mass
                                  .Arg<ffi::Buffer<ffi::F64>>()  // kappa
                                  .Arg<ffi::Buffer<ffi::F64>>()  // overlap0
                                  .Arg<ffi::Buffer<ffi::F64>>()  // spring
                                  .Arg<ffi::Buffer<ffi::F64>>()  // external
                                  .Arg<ffi::Buffer<ffi::S64>>()  // channels
                                  .Attr<double>("dt")
                                  .Attr<int64_t>("steps_per_sample")
                                  .Attr<int64_t>("preload")
                                  .Attr<int64_t>("springs")
                                  .Attr<int64_t>("books")
                                  .Ret<ffi::Buffer<ffi::F64>>()  // state
                                  .RemainingRets());             // traces
