// The contact laws of `hertzchain.contact` as the fused kernels apply them, and the
// derivative rules JAX gives them (for the kernels' forward-mode tangents): one definition
// for the host kernels (`chain_kernel.cc`) and the one-thread-per-chain kernels
// (`chain_kernel_thread.cu`, host or CUDA). Operation for operation and in the order of the
// JAX kernel, so that every kernel agrees with it to round-off
// (`tests/test_batched.py::test_every_kernel_applies_the_laws_of_contact`).
#pragma once

#include <cmath>

#ifndef HC_HD
#define HC_HD
#endif

// On a GPU (one thread per chain) a contact's square root is taken in contact only: out of
// contact, where most of a chain's contacts are most of the time, a warp's threads branch
// past its instructions; the numbers are the same (sqrt(0) = 0). The vectorised host
// kernels keep the branch-free form. `-DHC_ALWAYS_ROOT` builds the GPU kernel without the
// branch (to measure it: benchmarks/README.md), `-DHC_BRANCH_ON_CONTACT=1` the host
// emulation with it.
#ifndef HC_BRANCH_ON_CONTACT
#if defined(__CUDA_ARCH__) && !defined(HC_ALWAYS_ROOT)
#define HC_BRANCH_ON_CONTACT 1
#else
#define HC_BRANCH_ON_CONTACT 0
#endif
#endif

namespace hertzchain {

// sqrt(delta_+) of a positive part delta_+ >= 0, m^0.5
HC_HD inline double RootOfPositive(double positive) {
#if HC_BRANCH_ON_CONTACT
  if (positive > 0.0) return std::sqrt(positive);
  return 0.0;
#else
  return std::sqrt(positive);
#endif
}

// contact.hertz_force: kappa delta_+ sqrt(delta_+), then (kSprings) + spring delta, N
template <bool kSprings>
HC_HD inline double ElasticForce(double overlap, double kappa, double spring) {
  double positive = overlap > 0.0 ? overlap : 0.0;
  double force = kappa * positive * RootOfPositive(positive);
  if (kSprings) force = force + spring * overlap;
  return force;
}

// contact.power_law_force: kappa r^1.5 (delta / r)^n in contact (delta > 0), else 0, N
// (exponent n, reference overlap r, m); `ratio` = delta / r in contact, else 1 (the double
// `where` of `contact`), `rn` = ratio^n.
HC_HD inline double PowerLawForce(double overlap, double kappa, double n, double r, double* ratio, double* rn) {
  const bool in = overlap > 0.0;
  *ratio = in ? overlap / r : 1.0;
  *rn = std::pow(*ratio, n);
  const double force = kappa * std::pow(r, 1.5) * *rn;
  return in ? force : 0.0;
}

// The partial derivatives of `PowerLawForce` by overlap, kappa, r and n (as JAX's rules for
// `/`, `**` and `where` give them: d x^y = y x^(y - 1) dx + log(x) x^y dy), zero out of contact.
struct PowerLawSlopes {
  double overlap, kappa, reference, exponent;
};

HC_HD inline PowerLawSlopes PowerLawPartials(double overlap, double kappa, double n, double r, double ratio,
                                             double rn) {
  const double in = overlap > 0.0 ? 1.0 : 0.0;
  const double rp = std::pow(r, 1.5);
  const double by_ratio = kappa * rp * (n * std::pow(ratio, n - 1.0));  // d force / d ratio
  PowerLawSlopes d;
  d.overlap = in * (by_ratio / r);
  d.kappa = in * (rp * rn);
  d.reference = in * (kappa * (1.5 * std::sqrt(r)) * rn - by_ratio * (overlap / (r * r)));
  d.exponent = in * (kappa * rp * (std::log(ratio) * rn));
  return d;
}

// d max(s, 0) / ds as JAX's max rule gives it (1/2 at the tie)
HC_HD inline double MaxSlope(double s) {
  double tie = s == 0.0 ? 0.5 : 0.0;
  return s > 0.0 ? 1.0 : tie;
}

// contact.track_friction_kick: sign(w) max(|w| - loss, 0), m/s, with its speed minus loss s
// (as copysign: one instruction; at w = 0 the kept speed is 0, of w's sign)
HC_HD inline double Kick(double w, double loss, double* s) {
  double speed = std::fabs(w);
  *s = speed - loss;
  double kept = *s > 0.0 ? *s : 0.0;
  return std::copysign(kept, w);
}

// d kick = sign(w) max'(|w| - loss) (d|w| - d loss) as JAX's rules give it: with pm = +-1
// the slope of |w| (+1 at 0) and g = sign(w) max'(s) (0, +-1/2 or +-1), (pm t_w - t_loss) g.
// `KickTangent` computes it as (t_w - sg t_loss) m, with sg = copysign(1, w) and m = max'(s)
// where w != 0, else 0 (`KickSlope`): the same value (for w < 0, (-t_w - t_loss)(-m) =
// (t_w + t_loss) m exactly, rounding being symmetric and m a power of 2 or 0; at w = 0 both
// are a product with 0) from fewer operations per kick: no product of two selects.
HC_HD inline void KickSlope(double w, double s, double* sg, double* m) {
  *sg = std::copysign(1.0, w);
  *m = w != 0.0 ? MaxSlope(s) : 0.0;
}

// The tangent of a friction kick: t_w the kicked velocity's, t_loss the loss's, (sg, m) its
// `KickSlope`.
HC_HD inline double KickTangent(double t_w, double t_loss, double sg, double m) {
  return (t_w - sg * t_loss) * m;
}

// The dashpot a contact applies (`contact.contact_force`): none where there is no contact
// law (kappa = 0: a free end, a sensor spring), N s/m.
HC_HD inline double ContactDashpot(double k, double dashpot) { return k > 0.0 ? dashpot : 0.0; }

// contact.contact_force (the total, clipped at 0 in contact: Kuwabara-Kono damping with
// kv = 1.5 eta kappa, and with kDashpot a linear dashpot `dash` = `ContactDashpot`) at
// overlap dl (m) and rate (m/s), N; the root sqrt(dl_+) and the unclipped sum kept for the
// linearisation. Branch-free (selects only): sqrt(0) = 0 is the root out of contact, as
// `contact` has it, where elastic = viscous = 0; a dashpot would push there, so with one the
// total is also 0 out of contact. kDashpot is a compile-time switch: its terms cost every
// damped run about 17 % (`benchmarks/results/dashpot_kernel/history/dashpot_in_cpp_kernel_not_kept.md`), so only
// the runs that have a dashpot carry them.
// `TotalForce` about a given elastic force (`elastic`, N; the root sqrt(dl_+) `rt`): the
// damped sum, clipped, plus the spring (kExtras).
template <bool kViscous, bool kExtras, bool kDashpot>
HC_HD inline double DampedTotal(double elastic, double rt, double dl, double rate, double kv, double dash,
                                double sp, double* sum) {
  double f;
  if (kViscous) {
    double viscous = kDashpot ? (kv * rt + dash) * rate : (kv * rt) * rate;
    double s = elastic + viscous;
    *sum = s;
    if (kDashpot)
      f = dl > 0.0 && s > 0.0 ? s : 0.0;
    else
      f = s > 0.0 ? s : 0.0;
  } else {
    *sum = elastic;
    f = elastic;
  }
  if (kExtras) f = f + sp * dl;  // (a spring of 0 adds nothing)
  return f;
}

template <bool kViscous, bool kExtras, bool kDashpot>
HC_HD inline double TotalForce(double dl, double rate, double k, double kv, double dash, double sp, double* root,
                               double* sum) {
  double positive = dl > 0.0 ? dl : 0.0;
  double rt = RootOfPositive(positive);
  *root = rt;
  return DampedTotal<kViscous, kExtras, kDashpot>(k * positive * rt, rt, dl, rate, kv, dash, sp, sum);
}

// A contact's linearisation at overlap delta and rate: in = [delta > 0], positive =
// delta_+, root = sqrt(delta_+), half_inv_root = 0.5 / root in contact (JAX's sqrt rule)
// else 0, kp = kappa delta_+, c3 = 1.5 eta kappa root (+ the dashpot with kDashpot: the
// rate's coefficient), slope = max'(total) in contact else 0.
struct Linearisation {
  double delta, rate, in, positive, root, half_inv_root, kp, c3, slope;
};

template <bool kDashpot>
HC_HD inline Linearisation Linearise(double dl, double rate, double k, double kv, double dash, double root,
                                     double sum) {
  Linearisation l;
  l.delta = dl;
  l.rate = rate;
  l.in = dl > 0.0 ? 1.0 : 0.0;
  l.positive = dl > 0.0 ? dl : 0.0;
  l.root = root;
  l.half_inv_root = dl > 0.0 ? 0.5 / root : 0.0;
  l.kp = k * l.positive;
  l.c3 = kDashpot ? kv * root + dash : kv * root;
  l.slope = dl > 0.0 ? MaxSlope(sum) : 0.0;
  return l;
}

// The tangent of `TotalForce` along one direction: c1 = 1.5 eta, c2 = c1 kappa, sp the
// spring, tdl / trate / tk / t15e (= 1.5 t_eta) / tdash (`ContactDashpot`'s, read with
// kDashpot only) / tsp the inputs' tangents. The spring's terms are read with kExtras only,
// as `TotalForce` reads the spring: without them the force does not depend on it; and the
// spring's own tangent tsp with kSpringTangent only (a caller that knows it is 0 drops
// tsp delta = 0, which changes no value).
// `TangentForce` about the elastic force's tangent `telastic` (any law).
template <bool kViscous, bool kExtras, bool kDashpot, bool kSpringTangent = kExtras>
HC_HD inline double TangentTotal(const Linearisation& l, double telastic, double k, double c1, double c2, double sp,
                                 double tdl, double trate, double tk, double t15e, double tdash, double tsp) {
  double troot = tdl * l.half_inv_root;
  double tf = telastic;
  if (kViscous) {
    double tc3 = (t15e * k + c1 * tk) * l.root + c2 * troot;
    if (kDashpot) tc3 = tc3 + tdash;
    tf = (telastic + (tc3 * l.rate + l.c3 * trate)) * l.slope;
  }
  if (kExtras) tf = kSpringTangent ? tf + (tsp * l.delta + sp * tdl) : tf + sp * tdl;
  return tf;
}

template <bool kViscous, bool kExtras, bool kDashpot, bool kSpringTangent = kExtras>
HC_HD inline double TangentForce(const Linearisation& l, double k, double c1, double c2, double sp, double tdl,
                                 double trate, double tk, double t15e, double tdash, double tsp) {
  double tpositive = tdl * l.in;
  double troot = tdl * l.half_inv_root;
  double telastic = (tk * l.positive + k * tpositive) * l.root + l.kp * troot;
  return TangentTotal<kViscous, kExtras, kDashpot, kSpringTangent>(l, telastic, k, c1, c2, sp, tdl, trate, tk, t15e, tdash, tsp);
}

// ---------------------------------------------------------------------------------------
// Elastic-plastic contacts. Both laws of `contact` unload (and reload below the largest
// overlap so far, `peak`) along a Hertz curve about a residual overlap: force
// kp (delta - residual)_+^{3/2}, with (residual, kp) functions of the peak and the contact's
// constants alone (`Unloading`). Below first yield residual = 0 and kp = kappa: Hertz, to the
// bit. The kernels compute the pair when the peak grows, and the force every step from it.
// Written once over the number type T: `double` for the values and `Dual<N>` for their
// partial derivatives by the N inputs (forward mode, the chain rule applied operation by
// operation as JAX's jvp applies it).

template <int N>
struct Dual {
  double v;
  double d[N];
};

template <int N>
HC_HD inline Dual<N> Constant(double v) {
  Dual<N> r;
  r.v = v;
  for (int k = 0; k < N; ++k) r.d[k] = 0.0;
  return r;
}
// input k of N, at value v
template <int N>
HC_HD inline Dual<N> Input(double v, int k) {
  Dual<N> r = Constant<N>(v);
  r.d[k] = 1.0;
  return r;
}
// r = f(x) with f'(x) = slope
template <int N>
HC_HD inline Dual<N> Chain(double v, double slope, const Dual<N>& x) {
  Dual<N> r;
  r.v = v;
  for (int k = 0; k < N; ++k) r.d[k] = slope * x.d[k];
  return r;
}
template <int N>
HC_HD inline Dual<N> operator+(const Dual<N>& a, const Dual<N>& b) {
  Dual<N> r;
  r.v = a.v + b.v;
  for (int k = 0; k < N; ++k) r.d[k] = a.d[k] + b.d[k];
  return r;
}
template <int N>
HC_HD inline Dual<N> operator-(const Dual<N>& a, const Dual<N>& b) {
  Dual<N> r;
  r.v = a.v - b.v;
  for (int k = 0; k < N; ++k) r.d[k] = a.d[k] - b.d[k];
  return r;
}
template <int N>
HC_HD inline Dual<N> operator*(const Dual<N>& a, const Dual<N>& b) {
  Dual<N> r;
  r.v = a.v * b.v;
  for (int k = 0; k < N; ++k) r.d[k] = a.d[k] * b.v + a.v * b.d[k];
  return r;
}
template <int N>
HC_HD inline Dual<N> operator/(const Dual<N>& a, const Dual<N>& b) {
  Dual<N> r;
  r.v = a.v / b.v;
  for (int k = 0; k < N; ++k) r.d[k] = (a.d[k] - r.v * b.d[k]) / b.v;
  return r;
}
template <int N>
HC_HD inline Dual<N> operator+(const Dual<N>& a, double b) { return a + Constant<N>(b); }
template <int N>
HC_HD inline Dual<N> operator-(double a, const Dual<N>& b) { return Constant<N>(a) - b; }
template <int N>
HC_HD inline Dual<N> operator*(double a, const Dual<N>& b) { return Chain(a * b.v, a, b); }
template <int N>
HC_HD inline Dual<N> operator*(const Dual<N>& a, double b) { return Chain(a.v * b, b, a); }
template <int N>
HC_HD inline Dual<N> operator/(const Dual<N>& a, double b) { return Chain(a.v / b, 1.0 / b, a); }

// the constant v as a number of x's type
HC_HD inline double Like(double, double v) { return v; }
template <int N>
HC_HD inline Dual<N> Like(const Dual<N>&, double v) { return Constant<N>(v); }
HC_HD inline double Value(double x) { return x; }
HC_HD inline double Sqrt(double x) { return std::sqrt(x); }
HC_HD inline double Exp(double x) { return std::exp(x); }
HC_HD inline double Pow(double x, double y) { return std::pow(x, y); }
template <int N>
HC_HD inline double Value(const Dual<N>& x) { return x.v; }
template <int N>
HC_HD inline Dual<N> Sqrt(const Dual<N>& x) {
  const double r = std::sqrt(x.v);
  return Chain(r, 0.5 / r, x);
}
template <int N>
HC_HD inline Dual<N> Exp(const Dual<N>& x) {
  const double e = std::exp(x.v);
  return Chain(e, e, x);
}
// x^y, y a constant: y x^(y - 1) dx
template <int N>
HC_HD inline Dual<N> Pow(const Dual<N>& x, double y) {
  return Chain(std::pow(x.v, y), y * std::pow(x.v, y - 1.0), x);
}
// x^y (x > 0): y x^(y - 1) dx + log(x) x^y dy
template <int N>
HC_HD inline Dual<N> Pow(const Dual<N>& x, const Dual<N>& y) {
  Dual<N> r;
  r.v = std::pow(x.v, y.v);
  const double by_x = y.v * std::pow(x.v, y.v - 1.0), by_y = std::log(x.v) * r.v;
  for (int k = 0; k < N; ++k) r.d[k] = by_x * x.d[k] + by_y * y.d[k];
  return r;
}

// The unloading curve of an elastic-plastic contact: its residual overlap (m) and stiffness
// (N/m^{3/2}).
template <class T>
struct Unloading {
  T residual, kappa;
};

// contact.overlap_at_force: (F / kappa)^{2/3} for F > 0, else 0, m
template <class T>
HC_HD inline T HertzOverlap(const T& force, const T& kappa) {
  return Value(force) > 0.0 ? Pow(force / kappa, 2.0 / 3.0) : 0.0 * force;
}

// contact.thornton_contact's unloading curve after the largest overlap `peak` (m), with
// Hertz stiffness `kappa` and yield force `yield_force` (N, finite)
template <class T>
HC_HD inline Unloading<T> ThorntonUnloading(const T& peak, const T& kappa, const T& yield_force) {
  const T yield_overlap = HertzOverlap(yield_force, kappa);
  if (!(Value(peak) > Value(yield_overlap))) return {0.0 * peak, kappa};  // not yielded: Hertz
  const T yield_stiffness = 1.5 * yield_force / yield_overlap;
  const T max_force = yield_force + yield_stiffness * (peak - yield_overlap);
  const T radius_ratio = Pow((2.0 * max_force + yield_force) / 3.0, 1.5) / (max_force * Sqrt(yield_force));
  const T plastic_kappa = kappa * Sqrt(radius_ratio);
  return {peak - HertzOverlap(max_force, plastic_kappa), plastic_kappa};
}

// contact.jackson_green_contact: the hardness ratio h is the kernels' input (contact's
// JG_HARDNESS_RATIO in the chain), the transition ratio contact.JG_TRANSITION_RATIO and the
// constants of JG's fit are these
constexpr double kJgTransition = 1.9;

// JG's P / P_c at delta / delta_c = `ratio` with the hardness held at h sigma_Y
// (contact._jg_loading_ratio)
template <class T>
HC_HD inline T JgLoadingRatio(const T& ratio, const T& c, const T& hardness) {
  const T elastic = Exp(-0.25 * Pow(ratio, 5.0 / 12.0)) * Pow(ratio, 1.5);
  const T plastic = 4.0 * hardness / c * (1.0 - Exp(-1.0 * Pow(ratio, 5.0 / 9.0) / 25.0)) * ratio;
  return elastic + plastic;
}

// contact.jackson_green_contact's unloading curve after the largest overlap `peak` (m):
// Hertz stiffness `kappa`, reduced radius `radius` (m), yield stress `stress` (Pa), Poisson
// ratio `poisson`, hardness ratio `hardness`
template <class T>
HC_HD inline Unloading<T> JacksonGreenUnloading(const T& peak, const T& kappa, const T& radius, const T& stress,
                                               const T& poisson, const T& hardness) {
  const T modulus = 0.75 * kappa / Sqrt(radius);
  const T c = 1.295 * Exp(0.736 * poisson);
  const T critical = 3.141592653589793 * c * stress / (2.0 * modulus);
  const T delta_c = critical * critical * radius;
  const T ratio = peak / delta_c;
  if (!(Value(ratio) > kJgTransition)) return {0.0 * peak, kappa};  // not yielded: Hertz
  const T force_c = kappa * Pow(delta_c, 1.5);
  const T area_exponent = 0.14 * Exp(23.0 * stress / modulus);
  const T t = Like(peak, kJgTransition);
  const T loading = JgLoadingRatio(ratio, c, hardness) - JgLoadingRatio(t, c, hardness) + std::pow(kJgTransition, 1.5);
  const T max_force = force_c * loading;
  const T radius_sq = radius * peak * Pow(ratio / kJgTransition, area_exponent);
  const T span = 0.75 * max_force / (modulus * Sqrt(radius_sq));
  return {peak - span, max_force / Pow(span, 1.5)};
}

}  // namespace hertzchain
