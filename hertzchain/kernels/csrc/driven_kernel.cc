// The lock-in runs of driven chains (`hertzchain.driven.grid.lockin_grid`) as one fused
// host kernel: a block of runs at a time through all the steps of its run while the block's
// state sits in registers and L1, every contact's force computed once per step, the lock-in
// accumulated as the window's samples are made (nothing but the complex amplitudes leaves
// the kernel), and forward-mode tangents carried through the same loop.
//
// A run (`hertzchain.driven.kernel.step`, one harmonic level of `drive.harmonic_segment`):
// the driver's amplitude rises from 0 to the run's `amplitude` along the smooth step over
// `ramp_steps` steps and holds; step j (1..steps) of length dt:
//   v_half = v + h (f - gamma v),   x' = x + dt v_half,        (h = dt/2)
//   f'     = the contact forces' acceleration at x', the driver at u_j, the contacts' rates
//            at the predicted velocity v_half + h (f - gamma v) and the driver's u'_j,
//   v'     = (v_half + h f') / (1 + h gamma),
// with u_j = a S(j/R) cos(theta_j), u'_j = (a S'(j/R)/(R dt)) cos(theta_j) - a S(j/R) omega
// sin(theta_j), theta_j = 2 pi (j mod N)/N. The tables of cos, sin, S and S' (functions of
// the step alone, shared by every run) come from the JAX side, evaluated as the JAX kernel
// evaluates them. Over the last `window` steps the read bead's velocity or displacement is
// summed against the lock-in's reference (re, im of exp(-i phase) per harmonic and window
// step, from `lockin.lockin_steps`). The arithmetic is the JAX kernel's, operation for
// operation (no contraction into fused multiply-adds), the contact law `chain_laws.h`'s;
// the sums run in step order (XLA may sum in another order: they agree to round-off).
//
// Layouts: inv_mass, gamma (n, 1 or B); kappa, overlap0 (n + 1, 1 or B); eta (1, 1 or B);
// amplitude, dt, omega (1, 1 or B); cos, sin (N,); shape, slope (R + 1,) (R = 0: one
// entry, unread); reference (2, H, window). Result: (2, H, B), the sums' real then
// imaginary parts. The tangent kernel takes the eight arrays' tangents after them, each
// (D or 1, rows, B) (1: shared by every direction), and also returns (D, 2, H, B).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "xla/ffi/api/ffi.h"

#include "chain_blocks.h"
#include "chain_laws.h"

namespace ffi = xla::ffi;

namespace {

using hertzchain::AsParam;
using hertzchain::Block;
using hertzchain::Load;
using hertzchain::LoadTangent;
using hertzchain::Param;
using hertzchain::RunBlocks;
using hertzchain::Tangent;

// Runs advanced together: two AVX-512 vectors (the step's few contacts give each lane's
// chain of dependent operations little to overlap; two vectors per operation hide some of
// the square root's and the division's latency).
constexpr int64_t kLanes = 16;
constexpr double kZeros[kLanes] = {};  // the wall's displacement and velocity, and their tangents

struct Inputs {
  Param inv_mass, gamma, kappa, overlap0, eta, amplitude, dt, omega;
};

struct TangentInputs {
  Tangent inv_mass, gamma, kappa, overlap0, eta, amplitude, dt, omega;
};

struct Run {
  int64_t beads, steps, ramp_steps, steps_per_period, window, harmonics, row, batch;
  bool displacement;
  const double *cos, *sin, *shape, *slope, *reference;
};

// The inputs of a contact's force, in the order of its partial derivatives (`Slopes`): the
// overlap (m), kappa, and with damping the rate (m/s) and 1.5 eta (s).
constexpr int kOverlapIn = 0, kKappaIn = 1, kRateIn = 2, kEtaIn = 3;
constexpr int ForceInputs(bool viscous) { return viscous ? 4 : 2; }

// The partial derivatives of every contact's force by its inputs, input by input over the
// lanes of every contact (c, j) at c * kLanes + j, so that the tangents' lane loops vectorise.
struct Slopes {
  std::vector<double> by[4];
  Slopes(int64_t size, int inputs) {
    for (int k = 0; k < inputs; ++k) by[k].resize(size);
  }
};

// One block of kLanes runs from lo (lanes past the batch repeat its last run). kTangent:
// with the D directions' tangents of every state variable, each step's tangent computed
// right after the part of the primal step it differentiates (JAX's rules: products by the
// product rule, d(a / b) = da / b - (a / b) db / b).
template <bool kViscous, bool kTangent>
void RunDrivenBlock(const Run& r, int64_t lo, const Inputs& in, const TangentInputs& tin, int64_t D,
                    double* sums, double* tsums) {
  constexpr int64_t L = kLanes;
  const int64_t n = r.beads, c_rows = n + 1, valid = std::min(L, r.batch - lo), H = r.harmonics;
  std::vector<double> m(n * L), g(n * L), k(c_rows * L), o(c_rows * L), eta(L), a(L), dt(L), om(L);
  Load<L>(in.inv_mass, n, lo, m.data(), valid);
  Load<L>(in.gamma, n, lo, g.data(), valid);
  Load<L>(in.kappa, c_rows, lo, k.data(), valid);
  Load<L>(in.overlap0, c_rows, lo, o.data(), valid);
  Load<L>(in.eta, 1, lo, eta.data(), valid);
  Load<L>(in.amplitude, 1, lo, a.data(), valid);
  Load<L>(in.dt, 1, lo, dt.data(), valid);
  Load<L>(in.omega, 1, lo, om.data(), valid);
  const int64_t TD = kTangent ? D : 0;
  std::vector<double> tm(TD * n * L), tg(TD * n * L), tk(TD * c_rows * L), to(TD * c_rows * L);
  std::vector<double> teta(TD * L), ta(TD * L), tdt(TD * L), tom(TD * L);
  if (kTangent) {
    LoadTangent<L>(tin.inv_mass, D, n, r.batch, lo, tm.data(), valid);
    LoadTangent<L>(tin.gamma, D, n, r.batch, lo, tg.data(), valid);
    LoadTangent<L>(tin.kappa, D, c_rows, r.batch, lo, tk.data(), valid);
    LoadTangent<L>(tin.overlap0, D, c_rows, r.batch, lo, to.data(), valid);
    LoadTangent<L>(tin.eta, D, 1, r.batch, lo, teta.data(), valid);
    LoadTangent<L>(tin.amplitude, D, 1, r.batch, lo, ta.data(), valid);
    LoadTangent<L>(tin.dt, D, 1, r.batch, lo, tdt.data(), valid);
    LoadTangent<L>(tin.omega, D, 1, r.batch, lo, tom.data(), valid);
  }
  // per lane and run: h = dt/2, 1.5 eta, kv = 1.5 eta kappa (as JAX rounds it: (1.5 eta)
  // kappa), T = R dt (the ramp's duration), 1 + h gamma; and their tangents, with the
  // quotients of the quotient rule that are constant through the run (dT / T, d(1 + h
  // gamma) / (1 + h gamma)) computed once, and the divisions by T and 1 + h gamma as
  // products with their reciprocals (the tangents to round-off: a division per direction
  // and step cost the tangent run about a fifth of its time)
  const double ramp = static_cast<double>(r.ramp_steps);
  const bool ramping = r.ramp_steps > 0;
  std::vector<double> h(L), c1(L), kv(c_rows * L), ramp_time(L), den(n * L), inv_ramp_time(L), inv_den(n * L);
  std::vector<double> th(TD * L), t15e(TD * L), ramp_ratio(TD * L), den_ratio(TD * n * L);
  for (int64_t j = 0; j < L; ++j) {
    h[j] = 0.5 * dt[j];
    c1[j] = 1.5 * eta[j];
    ramp_time[j] = ramp * dt[j];
    inv_ramp_time[j] = 1.0 / ramp_time[j];
    for (int64_t c = 0; c < c_rows; ++c) kv[c * L + j] = 1.5 * eta[j] * k[c * L + j];
    for (int64_t i = 0; i < n; ++i) {
      den[i * L + j] = 1.0 + h[j] * g[i * L + j];
      inv_den[i * L + j] = 1.0 / den[i * L + j];
    }
    for (int64_t d = 0; d < TD; ++d) {
      const int64_t p = d * L + j;
      th[p] = 0.5 * tdt[p];
      t15e[p] = 1.5 * teta[p];
      ramp_ratio[p] = (ramp * tdt[p]) / ramp_time[j];
      for (int64_t i = 0; i < n; ++i) {
        const int64_t t = (d * n + i) * L + j;
        den_ratio[t] = (th[p] * g[i * L + j] + h[j] * tg[t]) / den[i * L + j];
      }
    }
  }
  // state (n, L): x, v and the contact forces' acceleration f; the step's half-kicked and
  // predicted velocities and its kick; the contacts' forces (n + 1, L); tangents (D, ...)
  std::vector<double> x(n * L, 0.0), v(n * L, 0.0), f(n * L), vh(n * L), vp(n * L), kick(n * L), F(c_rows * L);
  std::vector<double> tx(TD * n * L, 0.0), tv(TD * n * L, 0.0), tf(TD * n * L), tvh(TD * n * L), tvp(TD * n * L);
  std::vector<double> tF(c_rows * L);
  constexpr int kInputs = ForceInputs(kViscous);
  Slopes slopes(kTangent ? c_rows * L : 0, kInputs);
  std::vector<double> acc(2 * H * L, 0.0), tacc(TD * 2 * H * L, 0.0);

  // contact c of lane j at overlap dl and rate (`contact.contact_force`'s total, or Hertz
  // without damping), with kTangent its partial derivatives by its inputs (the law run on
  // dual numbers seeded with each input: kv = (1.5 eta) kappa as JAX rounds it)
  auto force = [&](int64_t c, int64_t j, double dl, double rate) {
    const int64_t q = c * L + j;
    if constexpr (kTangent) {
      using hertzchain::Seed;
      using hertzchain::SeedIf;
      const auto kd = Seed<kInputs, kKappaIn>(k[q]);
      const auto total = hertzchain::TotalForce<kViscous, false, false>(
          Seed<kInputs, kOverlapIn>(dl), SeedIf<kViscous, kInputs, kRateIn>(rate), kd,
          SeedIf<kViscous, kInputs, kEtaIn>(c1[j]) * kd, 0.0, 0.0);
      F[q] = total.v;
      for (int slot = 0; slot < kInputs; ++slot) slopes.by[slot][q] = hertzchain::Slope(total, slot);
    } else {
      F[q] = hertzchain::TotalForce<kViscous, false, false>(dl, rate, k[q], kv[q], 0.0, 0.0);
    }
  };
  // its tangent along direction d from the partials and the inputs' tangents
  auto tforce = [&](int64_t d, int64_t c, int64_t j, double tdl, double trate) {
    const int64_t q = c * L + j;
    double t = slopes.by[kOverlapIn][q] * tdl + slopes.by[kKappaIn][q] * tk[(d * c_rows + c) * L + j];
    if constexpr (kViscous) t = t + slopes.by[kRateIn][q] * trate + slopes.by[kEtaIn][q] * t15e[d * L + j];
    tF[q] = t;
  };
  // f = (F_i - F_{i+1}) m_i, and its tangent along direction d
  auto accelerations = [&]() {
    for (int64_t i = 0; i < n; ++i)
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) f[i * L + j] = (F[i * L + j] - F[(i + 1) * L + j]) * m[i * L + j];
  };
  auto taccelerations = [&](int64_t d) {
    for (int64_t i = 0; i < n; ++i)
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) {
        const int64_t t = (d * n + i) * L + j;
        tf[t] = (tF[i * L + j] - tF[(i + 1) * L + j]) * m[i * L + j] + (F[i * L + j] - F[(i + 1) * L + j]) * tm[t];
      }
  };

  // the static equilibrium (`kernel.static_state`): at rest, the driver at 0
  for (int64_t c = 0; c < c_rows; ++c)
    for (int64_t j = 0; j < L; ++j) force(c, j, (o[c * L + j] + 0.0) - 0.0, 0.0);
  accelerations();
  for (int64_t d = 0; d < TD; ++d) {
    for (int64_t c = 0; c < c_rows; ++c)
      for (int64_t j = 0; j < L; ++j) tforce(d, c, j, to[(d * c_rows + c) * L + j], 0.0);
    taccelerations(d);
  }

  const int64_t first_recorded = r.steps - r.window + 1;
  for (int64_t step = 1; step <= r.steps; ++step) {
    const int64_t phase = step % r.steps_per_period;
    const double cs = r.cos[phase], sn = r.sin[phase];
    const int64_t ramp_index = std::min(step, r.ramp_steps);
    const double shape = ramping ? r.shape[ramp_index] : 1.0, slope = ramping ? r.slope[ramp_index] : 0.0;
    // kick and drift
    for (int64_t i = 0; i < n; ++i)
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) {
        const int64_t q = i * L + j;
        kick[q] = h[j] * (f[q] - g[q] * v[q]);
        vh[q] = v[q] + kick[q];
        x[q] = x[q] + dt[j] * vh[q];
        vp[q] = vh[q] + kick[q];
      }
    for (int64_t d = 0; d < TD; ++d)
      for (int64_t i = 0; i < n; ++i)
#pragma GCC ivdep
        for (int64_t j = 0; j < L; ++j) {
          const int64_t q = i * L + j, t = (d * n + i) * L + j;
          const double tkick = th[d * L + j] * (f[q] - g[q] * v[q]) + h[j] * (tf[t] - (tg[t] * v[q] + g[q] * tv[t]));
          tvh[t] = tv[t] + tkick;
          tx[t] = tx[t] + (tdt[d * L + j] * vh[q] + dt[j] * tvh[t]);
          tvp[t] = tvh[t] + tkick;
        }
    // the driver (`drive.harmonic_segment` from 0 to a: from + change S, change = a; without
    // a ramp the amplitude at once) and the contacts' forces
    double u[L], ud[L], envelope[L], rate[L];
#pragma GCC ivdep
    for (int64_t j = 0; j < L; ++j) {
      envelope[j] = ramping ? a[j] * shape : a[j];
      rate[j] = ramping ? a[j] * slope / ramp_time[j] : 0.0;
      u[j] = envelope[j] * cs + 0.0;
      ud[j] = (rate[j] * cs - envelope[j] * om[j] * sn) + 0.0;
    }
    for (int64_t c = 0; c < c_rows; ++c) {
      // the bodies on either side: the driver (its motion + 0, as JAX pads it) or a bead,
      // and a bead or the wall (at rest)
      const double* __restrict front = c == 0 ? u : &x[(c - 1) * L];
      const double* __restrict back = c == n ? kZeros : &x[c * L];
      const double* __restrict front_v = c == 0 ? ud : &vp[(c - 1) * L];
      const double* __restrict back_v = c == n ? kZeros : &vp[c * L];
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) force(c, j, (o[c * L + j] + front[j]) - back[j], front_v[j] - back_v[j]);
    }
    accelerations();
    for (int64_t d = 0; d < TD; ++d) {
      double tu[L], tud[L];
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) {
        const int64_t p = d * L + j;
        const double tenvelope = ramping ? ta[p] * shape : ta[p];
        const double trate = ramping ? (ta[p] * slope) * inv_ramp_time[j] - rate[j] * ramp_ratio[p] : 0.0;
        tu[j] = tenvelope * cs;
        tud[j] = trate * cs - (tenvelope * om[j] + envelope[j] * tom[p]) * sn;
      }
      for (int64_t c = 0; c < c_rows; ++c) {
        const double* __restrict front = c == 0 ? tu : &tx[(d * n + c - 1) * L];
        const double* __restrict back = c == n ? kZeros : &tx[(d * n + c) * L];
        const double* __restrict front_v = c == 0 ? tud : &tvp[(d * n + c - 1) * L];
        const double* __restrict back_v = c == n ? kZeros : &tvp[(d * n + c) * L];
        const double* __restrict t_overlap0 = &to[(d * c_rows + c) * L];
#pragma GCC ivdep
        for (int64_t j = 0; j < L; ++j)
          tforce(d, c, j, (t_overlap0[j] + front[j]) - back[j], front_v[j] - back_v[j]);
      }
      taccelerations(d);
    }
    // the second half kick, implicit in the drag
    for (int64_t i = 0; i < n; ++i)
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) {
        const int64_t q = i * L + j;
        v[q] = (vh[q] + h[j] * f[q]) / den[q];
      }
    for (int64_t d = 0; d < TD; ++d)
      for (int64_t i = 0; i < n; ++i)
#pragma GCC ivdep
        for (int64_t j = 0; j < L; ++j) {
          const int64_t q = i * L + j, t = (d * n + i) * L + j;
          const double tnum = tvh[t] + (th[d * L + j] * f[q] + h[j] * tf[t]);
          tv[t] = tnum * inv_den[q] - v[q] * den_ratio[t];
        }
    // the lock-in's sums over the window
    if (step < first_recorded) continue;
    const int64_t w = step - first_recorded;
    for (int64_t d = -1; d < TD; ++d) {  // the values (d = -1), then every direction's tangents
      const double* __restrict y = d < 0 ? (r.displacement ? &x[r.row * L] : &v[r.row * L])
                                         : (r.displacement ? &tx[(d * n + r.row) * L] : &tv[(d * n + r.row) * L]);
      double* __restrict sum = d < 0 ? acc.data() : &tacc[d * 2 * H * L];
      for (int64_t hm = 0; hm < H; ++hm) {
        const double re = r.reference[hm * r.window + w], im = r.reference[(H + hm) * r.window + w];
        double* __restrict sum_re = &sum[hm * L];
        double* __restrict sum_im = &sum[(H + hm) * L];
#pragma GCC ivdep
        for (int64_t j = 0; j < L; ++j) {
          sum_re[j] = sum_re[j] + y[j] * re;
          sum_im[j] = sum_im[j] + y[j] * im;
        }
      }
    }
  }
  for (int64_t part = 0; part < 2 * H; ++part)
    for (int64_t j = 0; j < valid; ++j) sums[part * r.batch + lo + j] = acc[part * L + j];
  for (int64_t d = 0; d < TD; ++d)
    for (int64_t part = 0; part < 2 * H; ++part)
      for (int64_t j = 0; j < valid; ++j)
        tsums[(d * 2 * H + part) * r.batch + lo + j] = tacc[(d * 2 * H + part) * L + j];
}

Inputs AsInputs(const ffi::Buffer<ffi::F64>* b) {
  return {AsParam(b[0]), AsParam(b[1]), AsParam(b[2]), AsParam(b[3]),
          AsParam(b[4]), AsParam(b[5]), AsParam(b[6]), AsParam(b[7])};
}

// Checks the call's shapes and runs its blocks; `tangents` (8 buffers) null for the forward run.
ffi::Error RunDriven(ffi::ThreadPool& pool, const ffi::Buffer<ffi::F64>* arrays, const ffi::Buffer<ffi::F64>* tangents,
                     ffi::Buffer<ffi::F64> cos, ffi::Buffer<ffi::F64> sin, ffi::Buffer<ffi::F64> shape,
                     ffi::Buffer<ffi::F64> slope, ffi::Buffer<ffi::F64> reference, int64_t steps, int64_t ramp_steps,
                     int64_t row, int64_t displacement, int64_t viscous, ffi::Result<ffi::Buffer<ffi::F64>> sums,
                     ffi::Buffer<ffi::F64>* tsums) {
  auto sum_dims = sums->dimensions();
  if (sum_dims.size() != 3 || sum_dims[0] != 2) return ffi::Error::InvalidArgument("sums must be (2, H, B)");
  const int64_t harmonics = sum_dims[1], batch = sum_dims[2];
  auto mass_dims = arrays[0].dimensions();
  const int64_t beads = mass_dims[0];
  auto ref_dims = reference.dimensions();
  if (ref_dims.size() != 3 || ref_dims[0] != 2 || ref_dims[1] != harmonics)
    return ffi::Error::InvalidArgument("reference must be (2, H, window)");
  const int64_t window = ref_dims[2];
  const int64_t period = static_cast<int64_t>(cos.element_count());
  if (window < 1 || window > steps || row < 0 || row >= beads || period < 1 ||
      static_cast<int64_t>(sin.element_count()) != period ||
      static_cast<int64_t>(shape.element_count()) != std::max<int64_t>(ramp_steps, 0) + 1 ||
      slope.element_count() != shape.element_count())
    return ffi::Error::InvalidArgument("inconsistent window, bead, phase or ramp tables");
  Run r{beads, steps, ramp_steps, period, window, harmonics, row, batch, displacement != 0,
        cos.typed_data(), sin.typed_data(), shape.typed_data(), slope.typed_data(), reference.typed_data()};
  const Inputs in = AsInputs(arrays);
  TangentInputs tin{};
  int64_t D = 0;
  if (tangents) {
    const int64_t rows[8] = {beads, beads, beads + 1, beads + 1, 1, 1, 1, 1};
    int64_t counts[8];
    for (int i = 0; i < 8; ++i) {
      counts[i] = hertzchain::Directions(tangents[i], rows[i], batch);
      D = std::max(D, counts[i]);
    }
    for (int i = 0; i < 8; ++i)
      if (counts[i] != 1 && counts[i] != D)
        return ffi::Error::InvalidArgument("tangents must be (directions or 1, rows, B)");
    auto t = [&](int i) { return Tangent{tangents[i].typed_data(), counts[i] == 1}; };
    tin = {t(0), t(1), t(2), t(3), t(4), t(5), t(6), t(7)};
  }
  std::vector<Block> blocks;
  for (int64_t lo = 0; lo < batch; lo += kLanes) blocks.push_back({lo, kLanes});
  double* out = sums->typed_data();
  double* tout = tsums ? tsums->typed_data() : nullptr;
  auto run = [&](auto viscous_tag, auto tangent_tag) {
    constexpr bool kV = decltype(viscous_tag)::value, kT = decltype(tangent_tag)::value;
    RunBlocks(pool, blocks, [&](int64_t b) { RunDrivenBlock<kV, kT>(r, blocks[b].lo, in, tin, D, out, tout); });
  };
  using T = std::true_type;
  using F = std::false_type;
  if (tangents)
    viscous ? run(T{}, T{}) : run(F{}, T{});
  else
    viscous ? run(T{}, F{}) : run(F{}, F{});
  return ffi::Error::Success();
}

ffi::Error Forward(ffi::ThreadPool pool, ffi::Buffer<ffi::F64> inv_mass, ffi::Buffer<ffi::F64> gamma,
                   ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> eta,
                   ffi::Buffer<ffi::F64> amplitude, ffi::Buffer<ffi::F64> dt, ffi::Buffer<ffi::F64> omega,
                   ffi::Buffer<ffi::F64> cos, ffi::Buffer<ffi::F64> sin, ffi::Buffer<ffi::F64> shape,
                   ffi::Buffer<ffi::F64> slope, ffi::Buffer<ffi::F64> reference, int64_t steps, int64_t ramp_steps,
                   int64_t row, int64_t displacement, int64_t viscous, ffi::Result<ffi::Buffer<ffi::F64>> sums) {
  const ffi::Buffer<ffi::F64> arrays[8] = {inv_mass, gamma, kappa, overlap0, eta, amplitude, dt, omega};
  return RunDriven(pool, arrays, nullptr, cos, sin, shape, slope, reference, steps, ramp_steps, row, displacement,
                   viscous, sums, nullptr);
}

ffi::Error Tangents(ffi::ThreadPool pool, ffi::Buffer<ffi::F64> inv_mass, ffi::Buffer<ffi::F64> gamma,
                    ffi::Buffer<ffi::F64> kappa, ffi::Buffer<ffi::F64> overlap0, ffi::Buffer<ffi::F64> eta,
                    ffi::Buffer<ffi::F64> amplitude, ffi::Buffer<ffi::F64> dt, ffi::Buffer<ffi::F64> omega,
                    ffi::Buffer<ffi::F64> t_inv_mass, ffi::Buffer<ffi::F64> t_gamma, ffi::Buffer<ffi::F64> t_kappa,
                    ffi::Buffer<ffi::F64> t_overlap0, ffi::Buffer<ffi::F64> t_eta,
                    ffi::Buffer<ffi::F64> t_amplitude, ffi::Buffer<ffi::F64> t_dt, ffi::Buffer<ffi::F64> t_omega,
                    ffi::Buffer<ffi::F64> cos, ffi::Buffer<ffi::F64> sin, ffi::Buffer<ffi::F64> shape,
                    ffi::Buffer<ffi::F64> slope, ffi::Buffer<ffi::F64> reference, int64_t steps, int64_t ramp_steps,
                    int64_t row, int64_t displacement, int64_t viscous, ffi::Result<ffi::Buffer<ffi::F64>> sums,
                    ffi::Result<ffi::Buffer<ffi::F64>> tsums) {
  const ffi::Buffer<ffi::F64> arrays[8] = {inv_mass, gamma, kappa, overlap0, eta, amplitude, dt, omega};
  const ffi::Buffer<ffi::F64> tangents[8] = {t_inv_mass, t_gamma, t_kappa, t_overlap0, t_eta, t_amplitude, t_dt,
                                             t_omega};
  ffi::Buffer<ffi::F64> tout = *tsums;
  return RunDriven(pool, arrays, tangents, cos, sin, shape, slope, reference, steps, ramp_steps, row, displacement,
                   viscous, sums, &tout);
}

// kCount (>= 1) more f64 buffer arguments of a handler's binding (a binding cannot be
// moved: each step returns the new one its `Arg` makes)
template <int kCount, class Binding>
auto Buffers(Binding&& binding) {
  if constexpr (kCount == 1) {
    return std::forward<Binding>(binding).template Arg<ffi::Buffer<ffi::F64>>();
  } else {
    return Buffers<kCount - 1>(std::forward<Binding>(binding).template Arg<ffi::Buffer<ffi::F64>>());
  }
}

// inv_mass, gamma, kappa, overlap0, eta, amplitude, dt, omega
template <class Binding>
auto Arrays(Binding&& binding) {
  return Buffers<8>(std::forward<Binding>(binding));
}

// the tables cos, sin, shape, slope and reference, then the attributes
template <class Binding>
auto TablesAndAttrs(Binding&& binding) {
  return Buffers<5>(std::forward<Binding>(binding))
      .template Attr<int64_t>("steps")
      .template Attr<int64_t>("ramp_steps")
      .template Attr<int64_t>("row")
      .template Attr<int64_t>("displacement")
      .template Attr<int64_t>("viscous");
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainDrivenLockin, Forward,
                              TablesAndAttrs(Arrays(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>()))
                                  .Ret<ffi::Buffer<ffi::F64>>());  // sums (2, H, B)

XLA_FFI_DEFINE_HANDLER_SYMBOL(HertzChainDrivenLockinTangent, Tangents,
                              TablesAndAttrs(Arrays(Arrays(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>())))
                                  .Ret<ffi::Buffer<ffi::F64>>()    // sums (2, H, B)
                                  .Ret<ffi::Buffer<ffi::F64>>());  // their tangents (D, 2, H, B)
