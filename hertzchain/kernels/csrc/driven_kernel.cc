// The lock-in runs of driven chains (`hertzchain.driven.grid.lockin_grid`) as one fused
// host kernel: a block of runs at a time through all the steps of its run while the block's
// state sits in registers and L1, every contact's force computed once per step, the lock-in
// accumulated as the window's samples are made (nothing but the complex amplitudes leaves
// the kernel), and forward-mode tangents carried through the same loop: each phase of the
// step is written once over its number type, run on doubles for the values and on dual
// numbers along every tangent direction (`DrivenBlock`), the contact law's partial
// derivatives from the law run once on dual numbers seeded with its inputs.
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
#include "chain_lanes.h"
#include "chain_laws.h"
#include "chain_verlet.h"

namespace ffi = xla::ffi;

namespace {

using hertzchain::AsParam;
using hertzchain::Block;
using hertzchain::ForLanes;
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

// The partial derivatives of every contact's force by its inputs (the law run on dual
// numbers seeded with each input), input by input over the lanes of every contact (c, j) at
// c * kLanes + j, so that the tangents' lane loops vectorise.
struct Slopes {
  std::vector<double> by[4];
  Slopes(int64_t size, int inputs) {
    for (int k = 0; k < inputs; ++k) by[k].resize(size);
  }
};

// The step's numbers: doubles for the values, dual numbers along one tangent direction for
// the tangents (the same operations on them: JAX's jvp rules).
using Dual1 = hertzchain::Dual<1, 1u>;

// a kick without friction (`chain_verlet.h`'s phases take the kick as a function)
struct Identity {
  template <class T>
  HC_INLINE T operator()(const T& w) const {
    return w;
  }
};

// num / den for a den constant through the run, inv its reciprocal: the quotient for the
// values (as JAX divides), the product with the reciprocal for dual numbers (the same
// derivative: no division per direction and step, a fifth of the tangent run's time)
HC_INLINE double Over(double num, double den, double) { return num / den; }
HC_INLINE Dual1 Over(const Dual1& num, const Dual1&, const Dual1& inv) { return num * inv; }

// A run's constants of one lane (and bead): h = dt/2, 1.5 eta, T = R dt (the ramp's
// duration) and its reciprocal, 1 + h gamma and its reciprocal
template <class T>
struct RunConstants {
  T h, c1, ramp_time, inv_ramp_time;
};
template <class T>
HC_INLINE RunConstants<T> Constants(const T& dt, const T& eta, double ramp) {
  const T ramp_time = ramp * dt;
  return {0.5 * dt, 1.5 * eta, ramp_time, 1.0 / ramp_time};
}

// the driver (`drive.harmonic_segment` from 0 to a: from + change S, change = a; without a
// ramp the amplitude at once) at the step's cos, sin, S and S': its motion u and rate u'
// (+ 0, as JAX pads them); T the ramp's duration, inv_T its reciprocal
template <class T>
HC_INLINE void Driver(const T& a, const T& om, const T& ramp_time, const T& inv_ramp_time, bool ramping, double shape,
                      double slope, double cs, double sn, T& u, T& rate_u) {
  const T envelope = ramping ? a * shape : a;
  const T rate = ramping ? Over(a * slope, ramp_time, inv_ramp_time) : hertzchain::Like(a, 0.0);
  u = envelope * cs + 0.0;
  rate_u = (rate * cs - envelope * om * sn) + 0.0;
}

// A row of a (rows, kLanes) block: its values and (a direction's) tangents; `At` reads lane
// j as a number of type T (a double: the value; a dual number: with its tangent), `Put`
// writes a double's value or a dual number's tangent.
struct Row {
  const double* value;
  const double* tangent;
};
struct OutRow {
  double* value;
  double* tangent;
};
template <class T>
HC_INLINE T At(const Row& row, int64_t j) {
  if constexpr (std::is_same_v<T, double>) {
    return row.value[j];
  } else {
    return hertzchain::Along(row.value[j], row.tangent[j]);
  }
}
HC_INLINE void Put(double x, const OutRow& row, int64_t j) { row.value[j] = x; }
HC_INLINE void Put(const Dual1& x, const OutRow& row, int64_t j) { row.tangent[j] = x.d[0]; }

// One block of kLanes runs from lo (lanes past the batch repeat its last run): its inputs,
// state and tangents (D directions) as (rows, kLanes) blocks, and the step's phases. Each
// phase is written once over its number type T and run on doubles (the values, `d` = -1)
// and, kTangent, on dual numbers along every direction d before the values move on.
template <bool kViscous, bool kTangent>
struct DrivenBlock {
  static constexpr int64_t L = kLanes;
  static constexpr int kInputs = ForceInputs(kViscous);
  const Run& r;
  const int64_t n, c_rows, valid, H, D;
  const bool ramping;
  // inputs (rows, L) and their tangents (D, rows, L)
  std::vector<double> m, g, k, o, eta, a, dt, om, tm, tg, tk, to, teta, ta, tdt, tom;
  // the run's constants (`RunConstants`; rc: h, c1, ramp time, its reciprocal, row by row),
  // 1 + h gamma and its reciprocal (n, L), 1.5 eta kappa (as JAX rounds it: (1.5 eta)
  // kappa); and their tangents
  std::vector<double> rc, den, inv_den, kv, trc, tden, tinv_den;
  // state (n, L): x, v and the contact forces' acceleration f; the step's half-kicked and
  // predicted velocities; the contacts' forces (n + 1, L); tangents (D, ...)
  std::vector<double> x, v, f, vh, vp, F, tx, tv, tf, tvh, tvp, tF;
  Slopes slopes;
  std::vector<double> acc, tacc;  // the lock-in's sums (2 H, L) and their tangents (D, 2 H, L)
  double u[L], ud[L];             // the driver's motion and rate this step

  DrivenBlock(const Run& r_, int64_t lo, const Inputs& in, const TangentInputs& tin, int64_t directions)
      : r(r_), n(r_.beads), c_rows(r_.beads + 1), valid(std::min(L, r_.batch - lo)), H(r_.harmonics),
        D(kTangent ? directions : 0), ramping(r_.ramp_steps > 0), m(n * L), g(n * L), k(c_rows * L),
        o(c_rows * L), eta(L), a(L), dt(L), om(L), tm(D * n * L), tg(D * n * L), tk(D * c_rows * L),
        to(D * c_rows * L), teta(D * L), ta(D * L), tdt(D * L), tom(D * L), rc(4 * L), den(n * L),
        inv_den(n * L), kv(c_rows * L), trc(D * 4 * L), tden(D * n * L), tinv_den(D * n * L), x(n * L, 0.0),
        v(n * L, 0.0), f(n * L), vh(n * L), vp(n * L), F(c_rows * L), tx(D * n * L, 0.0), tv(D * n * L, 0.0),
        tf(D * n * L), tvh(D * n * L), tvp(D * n * L), tF(c_rows * L), slopes(kTangent ? c_rows * L : 0, kInputs),
        acc(2 * H * L, 0.0), tacc(D * 2 * H * L, 0.0) {
    const Param params[8] = {in.inv_mass, in.gamma, in.kappa, in.overlap0, in.eta, in.amplitude, in.dt, in.omega};
    const Tangent tangents[8] = {tin.inv_mass, tin.gamma,     tin.kappa, tin.overlap0,
                                 tin.eta,      tin.amplitude, tin.dt,    tin.omega};
    std::vector<double>* values[8] = {&m, &g, &k, &o, &eta, &a, &dt, &om};
    std::vector<double>* tvalues[8] = {&tm, &tg, &tk, &to, &teta, &ta, &tdt, &tom};
    const int64_t rows[8] = {n, n, c_rows, c_rows, 1, 1, 1, 1};
    for (int p = 0; p < 8; ++p) {
      Load<L>(params[p], rows[p], lo, values[p]->data(), valid);
      if (kTangent) LoadTangent<L>(tangents[p], D, rows[p], r.batch, lo, tvalues[p]->data(), valid);
    }
    Prepare<double>(-1);
    for (int64_t d = 0; d < D; ++d) Prepare<Dual1>(d);
    for (int64_t c = 0; c < c_rows; ++c)
      for (int64_t j = 0; j < L; ++j) kv[c * L + j] = rc[L + j] * k[c * L + j];
  }

  // row `row` of a (rows, L) block `value` and, along direction d >= 0, of its tangents
  // (D, rows, L); `Out`: the same to write
  static Row In(const std::vector<double>& value, const std::vector<double>& tangent, int64_t row, int64_t rows,
                int64_t d) {
    return {&value[row * L], d < 0 ? nullptr : &tangent[(d * rows + row) * L]};
  }
  static OutRow Out(std::vector<double>& value, std::vector<double>& tangent, int64_t row, int64_t rows,
                    int64_t d) {
    return {&value[row * L], d < 0 ? nullptr : &tangent[(d * rows + row) * L]};
  }
  // the run's constants (`Constants`, 1 + h gamma and its reciprocal) along direction d
  template <class T>
  void Prepare(int64_t d) {
    for (int64_t j = 0; j < L; ++j) {
      const RunConstants<T> c =
          Constants(At<T>(In(dt, tdt, 0, 1, d), j), At<T>(In(eta, teta, 0, 1, d), j), static_cast<double>(r.ramp_steps));
      const T parts[4] = {c.h, c.c1, c.ramp_time, c.inv_ramp_time};
      for (int row = 0; row < 4; ++row) Put(parts[row], Out(rc, trc, row, 4, d), j);
      for (int64_t i = 0; i < n; ++i) {
        const T one_plus = 1.0 + c.h * At<T>(In(g, tg, i, n, d), j);
        Put(one_plus, Out(den, tden, i, n, d), j);
        Put(1.0 / one_plus, Out(inv_den, tinv_den, i, n, d), j);
      }
    }
  }

  // kick and drift of every bead along direction d
  template <class T>
  HC_INLINE void Drift(int64_t d) {
    const Row h_row = In(rc, trc, 0, 4, d), dt_row = In(dt, tdt, 0, 1, d);
    for (int64_t i = 0; i < n; ++i) {
      const Row x_in = In(x, tx, i, n, d), v_in = In(v, tv, i, n, d), f_in = In(f, tf, i, n, d);
      const Row g_in = In(g, tg, i, n, d);
      const OutRow x_out = Out(x, tx, i, n, d), half = Out(vh, tvh, i, n, d), pred = Out(vp, tvp, i, n, d);
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) {
        // (`chain_verlet.h`: the drag in the first half kick's acceleration f - gamma v)
        const T velocity = At<T>(v_in, j);
        T position = At<T>(x_in, j), predicted;
        const T half_v = hertzchain::HalfKickAndDrift(velocity, At<T>(f_in, j) - At<T>(g_in, j) * velocity,
                                                      At<T>(h_row, j), At<T>(dt_row, j), Identity{}, position,
                                                      predicted);
        Put(position, x_out, j);
        Put(half_v, half, j);
        Put(predicted, pred, j);
      }
    }
  }

  // contact c of lane j at overlap dl and rate (`contact.contact_force`'s total, or Hertz
  // without damping), with kTangent its partial derivatives by its inputs (the law run on
  // dual numbers seeded with each input)
  HC_INLINE void Force(int64_t c, int64_t j, double dl, double rate) {
    const int64_t q = c * L + j;
    if constexpr (kTangent) {
      using hertzchain::Seed;
      using hertzchain::SeedIf;
      const auto kd = Seed<kInputs, kKappaIn>(k[q]);
      const auto total = hertzchain::TotalForce<kViscous, false, false>(
          Seed<kInputs, kOverlapIn>(dl), SeedIf<kViscous, kInputs, kRateIn>(rate), kd,
          SeedIf<kViscous, kInputs, kEtaIn>(rc[L + j]) * kd, 0.0, 0.0);
      F[q] = total.v;
      for (int slot = 0; slot < kInputs; ++slot) slopes.by[slot][q] = hertzchain::Slope(total, slot);
    } else {
      F[q] = hertzchain::TotalForce<kViscous, false, false>(dl, rate, k[q], kv[q], 0.0, 0.0);
    }
  }
  // its tangent along direction d from the partials and the inputs' tangents
  HC_INLINE void ForceTangent(int64_t d, int64_t c, int64_t j, double tdl, double trate) {
    const int64_t q = c * L + j;
    double t = slopes.by[kOverlapIn][q] * tdl + slopes.by[kKappaIn][q] * tk[(d * c_rows + c) * L + j];
    if constexpr (kViscous) t = t + slopes.by[kRateIn][q] * trate + slopes.by[kEtaIn][q] * trc[(d * 4 + 1) * L + j];
    tF[q] = t;
  }

  // every contact's force along direction d: between the driver (c = 0; its motion and
  // rate `drive`, `drive_rate`) or a bead and a bead or the wall (c = n, at rest), at the
  // overlap (overlap0 + front) - back and the predicted rate; then the accelerations
  // f = (F_i - F_{i+1}) m_i. At rest (`kernel.static_state`, the driver at 0) with `at_rest`.
  template <class T>
  HC_INLINE void Forces(int64_t d, bool at_rest, Row drive, Row drive_rate) {
    const Row zero{kZeros, kZeros};
    for (int64_t c = 0; c < c_rows; ++c) {
      const Row front = at_rest ? zero : c == 0 ? drive : In(x, tx, c - 1, n, d);
      const Row back = at_rest || c == n ? zero : In(x, tx, c, n, d);
      const Row front_v = at_rest ? zero : c == 0 ? drive_rate : In(vp, tvp, c - 1, n, d);
      const Row back_v = at_rest || c == n ? zero : In(vp, tvp, c, n, d);
      const Row overlap0 = In(o, to, c, c_rows, d);
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) {
        const T dl = (At<T>(overlap0, j) + At<T>(front, j)) - At<T>(back, j);
        const T rate = At<T>(front_v, j) - At<T>(back_v, j);
        if constexpr (std::is_same_v<T, double>)
          Force(c, j, dl, rate);
        else
          ForceTangent(d, c, j, dl.d[0], rate.d[0]);
      }
    }
    for (int64_t i = 0; i < n; ++i) {
      const Row front{&F[i * L], &tF[i * L]}, back{&F[(i + 1) * L], &tF[(i + 1) * L]}, mass = In(m, tm, i, n, d);
      const OutRow out = Out(f, tf, i, n, d);
#pragma GCC ivdep
      for (int64_t j = 0; j < L; ++j) Put((At<T>(front, j) - At<T>(back, j)) * At<T>(mass, j), out, j);
    }
  }

  // the driver at this step and the contacts' forces along direction d
  template <class T>
  HC_INLINE void DriveAndForces(int64_t d, double shape, double slope, double cs, double sn) {
    double tu[L], tud[L];
    const Row a_in = In(a, ta, 0, 1, d), om_in = In(om, tom, 0, 1, d);
    const Row ramp_time = In(rc, trc, 2, 4, d), inv_ramp_time = In(rc, trc, 3, 4, d);
#pragma GCC ivdep
    for (int64_t j = 0; j < L; ++j) {
      T motion, rate;
      Driver(At<T>(a_in, j), At<T>(om_in, j), At<T>(ramp_time, j), At<T>(inv_ramp_time, j), ramping, shape, slope, cs,
             sn, motion, rate);
      Put(motion, OutRow{u, tu}, j);
      Put(rate, OutRow{ud, tud}, j);
    }
    Forces<T>(d, false, Row{u, tu}, Row{ud, tud});
  }

  // the second half kick, implicit in the drag: v' = (v_half + h f') / (1 + h gamma). The
  // values' lane loop is kept rolled: unrolled in full, GCC vectorised the loop over the
  // beads instead, and the forward run took 11 % more instructions
  // (`benchmarks/results/native_step/driven_and_thread.json`).
  template <class T>
  HC_INLINE void Kick(int64_t d) {
    const Row h_row = In(rc, trc, 0, 4, d);
    for (int64_t i = 0; i < n; ++i) {
      const Row half = In(vh, tvh, i, n, d), f_in = In(f, tf, i, n, d);
      const Row den_in = In(den, tden, i, n, d), inv_in = In(inv_den, tinv_den, i, n, d);
      const OutRow out = Out(v, tv, i, n, d);
      auto lane = [&](int64_t j) HC_LANES {
        // (`chain_verlet.h`, the drag implicit: the kick divides by 1 + h gamma)
        const auto implicit_drag = [&](const T& num) HC_LANES { return Over(num, At<T>(den_in, j), At<T>(inv_in, j)); };
        Put(hertzchain::SecondHalfKick(At<T>(half, j), At<T>(f_in, j), At<T>(h_row, j), implicit_drag), out, j);
      };
      ForLanes<L, std::is_same_v<T, double>>(lane);
    }
  }

  // the lock-in's sums over the window at window step w: the values (d = -1), then every
  // direction's tangents
  void LockIn(int64_t w) {
    for (int64_t d = -1; d < D; ++d) {
      const std::vector<double>& read = d < 0 ? (r.displacement ? x : v) : (r.displacement ? tx : tv);
      const double* __restrict y = &read[((d < 0 ? 0 : d * n) + r.row) * L];
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

  // a phase along every direction's tangents (before the values move on), then the values
  template <class Phase>
  HC_INLINE void Tangents(const Phase& phase) {
    if constexpr (kTangent)
      for (int64_t d = 0; d < D; ++d) phase(Dual1{}, d);
  }

  // the run: the static equilibrium, then every step, the window's samples into the sums
  void RunSteps(double* sums, double* tsums, int64_t lo) {
    Forces<double>(-1, true, Row{kZeros, kZeros}, Row{kZeros, kZeros});
    Tangents([&](auto t, int64_t d) { Forces<decltype(t)>(d, true, Row{kZeros, kZeros}, Row{kZeros, kZeros}); });
    const int64_t first_recorded = r.steps - r.window + 1;
    for (int64_t step = 1; step <= r.steps; ++step) {
      const int64_t phase = step % r.steps_per_period, ramp_index = std::min(step, r.ramp_steps);
      const double cs = r.cos[phase], sn = r.sin[phase];
      const double shape = ramping ? r.shape[ramp_index] : 1.0, slope = ramping ? r.slope[ramp_index] : 0.0;
      Tangents([&](auto t, int64_t d) { Drift<decltype(t)>(d); });
      Drift<double>(-1);
      DriveAndForces<double>(-1, shape, slope, cs, sn);  // (the values first: their partials)
      Tangents([&](auto t, int64_t d) { DriveAndForces<decltype(t)>(d, shape, slope, cs, sn); });
      Tangents([&](auto t, int64_t d) { Kick<decltype(t)>(d); });
      Kick<double>(-1);
      if (step >= first_recorded) LockIn(step - first_recorded);
    }
    for (int64_t part = 0; part < 2 * H; ++part)
      for (int64_t j = 0; j < valid; ++j) sums[part * r.batch + lo + j] = acc[part * L + j];
    for (int64_t d = 0; d < D; ++d)
      for (int64_t part = 0; part < 2 * H; ++part)
        for (int64_t j = 0; j < valid; ++j)
          tsums[(d * 2 * H + part) * r.batch + lo + j] = tacc[(d * 2 * H + part) * L + j];
  }
};

// One block of kLanes runs from lo, with kTangent the D directions' tangents of every state
// variable.
template <bool kViscous, bool kTangent>
void RunDrivenBlock(const Run& r, int64_t lo, const Inputs& in, const TangentInputs& tin, int64_t D,
                    double* sums, double* tsums) {
  DrivenBlock<kViscous, kTangent> block(r, lo, in, tin, D);
  block.RunSteps(sums, tsums, lo);
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
