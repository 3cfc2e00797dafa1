// The contact laws of `hertzchain.contact` as the fused kernels apply them: one definition
// for the host kernels (`chain_kernel.cc`, `driven_kernel.cc`) and the one-thread-per-chain
// kernels (`chain_kernel_thread.cu`, host or CUDA). Operation for operation and in the order
// of the JAX kernel, so that every kernel agrees with it to round-off
// (`tests/test_batched.py::test_every_kernel_applies_the_laws_of_contact`). Every law is
// written once over its number types: `double` for the values, and `Dual<N, M>` (forward
// mode, the derivative rules JAX's jvp applies, operation by operation) for the kernels'
// tangents, which are the same functions run on dual numbers.
#pragma once

#include <cmath>

#ifndef HC_HD
#define HC_HD
#endif

// Every law and every operation on dual numbers inlined where it is used, so that the loops
// over a block's chains that run them vectorise (a kernel's function is large enough that
// the compiler's own limits left the laws on duals as calls, and the loops scalar).
// And the loops over a dual number's components unrolled (they are a handful, known at
// compile time; a loop left rolled keeps the number in memory).
#if defined(__CUDACC__)
#define HC_INLINE __forceinline__
#define HC_UNROLL _Pragma("unroll")
#else
#define HC_INLINE inline __attribute__((always_inline))
#define HC_UNROLL _Pragma("GCC unroll 16")
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

// ---------------------------------------------------------------------------------------
// Dual numbers: a value and its partial derivatives by N inputs. `M` is the set of inputs
// the number can depend on (bit k: input k), known at compile time: a seeded input depends
// on itself alone, and an operation on two numbers on either's inputs, so that no partial
// that is 0 by construction is ever computed (a contact's force reads six inputs, each of
// its steps two or three). Components outside M are never read (`Slope` gives 0 for them).

HC_HD constexpr unsigned AllInputs(int n) { return n >= 32 ? ~0u : (1u << n) - 1u; }
HC_HD constexpr bool Has(unsigned m, int k) { return ((m >> k) & 1u) != 0u; }

template <int N, unsigned M = AllInputs(N)>
struct Dual {
  double v;
  double d[N];
};

// the partial derivative by input k
template <int N, unsigned M>
HC_HD HC_INLINE double Slope(const Dual<N, M>& x, int k) {
  return Has(M, k) ? x.d[k] : 0.0;
}

// input k of N at value v, depending on itself alone
template <int N, int K>
HC_HD HC_INLINE Dual<N, 1u << K> Seed(double v) {
  Dual<N, 1u << K> r;
  r.v = v;
  r.d[K] = 1.0;
  return r;
}
// `Seed<N, K>(v)` where kIs, else the constant v (an input that is not one in this run)
template <bool kIs, int N, int K>
HC_HD HC_INLINE auto SeedIf(double v) {
  if constexpr (kIs) {
    return Seed<N, K>(v);
  } else {
    return v;
  }
}
// the value v with its tangent t along one direction (forward mode a direction at a time)
HC_HD HC_INLINE Dual<1, 1u> Along(double v, double t) {
  Dual<1, 1u> r;
  r.v = v;
  r.d[0] = t;
  return r;
}
// input k of N at value v, as a number of every input (`Dual<N>`)
template <int N>
HC_HD HC_INLINE Dual<N> Input(double v, int k) {
  Dual<N> r;
  r.v = v;
  HC_UNROLL
  for (int q = 0; q < N; ++q) r.d[q] = q == k ? 1.0 : 0.0;
  return r;
}

// x as a number of the inputs in M2 (a superset of its own)
template <class To>
struct Widen;
template <>
struct Widen<double> {
  HC_HD HC_INLINE static double From(double x) { return x; }
};
template <int N, unsigned M2>
struct Widen<Dual<N, M2>> {
  HC_HD HC_INLINE static Dual<N, M2> From(double x) {
    Dual<N, M2> r;
    r.v = x;
    HC_UNROLL
    for (int k = 0; k < N; ++k)
      if (Has(M2, k)) r.d[k] = 0.0;
    return r;
  }
  template <unsigned M>
  HC_HD HC_INLINE static Dual<N, M2> From(const Dual<N, M>& x) {
    static_assert((M & ~M2) == 0u, "a number widened to fewer inputs");
    Dual<N, M2> r;
    r.v = x.v;
    HC_UNROLL
    for (int k = 0; k < N; ++k)
      if (Has(M2, k)) r.d[k] = Has(M, k) ? x.d[k] : 0.0;
    return r;
  }
};

// the number type of an operation on an A and a B
template <class A, class B>
struct Common;
template <>
struct Common<double, double> {
  using type = double;
};
template <int N, unsigned A, unsigned B>
struct Common<Dual<N, A>, Dual<N, B>> {
  using type = Dual<N, A | B>;
};
template <int N, unsigned A>
struct Common<Dual<N, A>, double> {
  using type = Dual<N, A>;
};
template <int N, unsigned A>
struct Common<double, Dual<N, A>> {
  using type = Dual<N, A>;
};

// `where(c, a, b)`: the value and the derivatives of the branch taken
template <class A, class B>
HC_HD HC_INLINE typename Common<A, B>::type Select(bool c, const A& a, const B& b) {
  using T = typename Common<A, B>::type;
  return c ? Widen<T>::From(a) : Widen<T>::From(b);
}

// r = f(x) with f'(x) = slope
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Chain(double v, double slope, const Dual<N, M>& x) {
  Dual<N, M> r;
  r.v = v;
  HC_UNROLL
  for (int k = 0; k < N; ++k)
    if (Has(M, k)) r.d[k] = slope * x.d[k];
  return r;
}
// r = f(a, b) with partial derivatives by_a, by_b: dr = by_a da + by_b db, in each direction
// only the terms of the arguments that carry it
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> Chain(double v, double by_a, const Dual<N, A>& a, double by_b, const Dual<N, B>& b) {
  Dual<N, A | B> r;
  r.v = v;
  HC_UNROLL
  for (int k = 0; k < N; ++k) {
    if (Has(A, k) && Has(B, k)) r.d[k] = by_a * a.d[k] + by_b * b.d[k];
    else if (Has(A, k)) r.d[k] = by_a * a.d[k];
    else if (Has(B, k)) r.d[k] = by_b * b.d[k];
  }
  return r;
}
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> operator+(const Dual<N, A>& a, const Dual<N, B>& b) {
  Dual<N, A | B> r;
  r.v = a.v + b.v;
  HC_UNROLL
  for (int k = 0; k < N; ++k) {
    if (Has(A, k) && Has(B, k)) r.d[k] = a.d[k] + b.d[k];
    else if (Has(A, k)) r.d[k] = a.d[k];
    else if (Has(B, k)) r.d[k] = b.d[k];
  }
  return r;
}
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> operator-(const Dual<N, A>& a, const Dual<N, B>& b) {
  Dual<N, A | B> r;
  r.v = a.v - b.v;
  HC_UNROLL
  for (int k = 0; k < N; ++k) {
    if (Has(A, k) && Has(B, k)) r.d[k] = a.d[k] - b.d[k];
    else if (Has(A, k)) r.d[k] = a.d[k];
    else if (Has(B, k)) r.d[k] = -b.d[k];
  }
  return r;
}
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> operator*(const Dual<N, A>& a, const Dual<N, B>& b) {
  Dual<N, A | B> r;
  r.v = a.v * b.v;
  HC_UNROLL
  for (int k = 0; k < N; ++k) {
    if (Has(A, k) && Has(B, k)) r.d[k] = a.d[k] * b.v + a.v * b.d[k];
    else if (Has(A, k)) r.d[k] = a.d[k] * b.v;
    else if (Has(B, k)) r.d[k] = a.v * b.d[k];
  }
  return r;
}
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> operator/(const Dual<N, A>& a, const Dual<N, B>& b) {
  Dual<N, A | B> r;
  r.v = a.v / b.v;
  HC_UNROLL
  for (int k = 0; k < N; ++k) {
    if (Has(A, k) && Has(B, k)) r.d[k] = (a.d[k] - r.v * b.d[k]) / b.v;
    else if (Has(A, k)) r.d[k] = a.d[k] / b.v;
    else if (Has(B, k)) r.d[k] = -(r.v * b.d[k]) / b.v;
  }
  return r;
}
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator-(const Dual<N, M>& a) { return Chain(-a.v, -1.0, a); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator+(const Dual<N, M>& a, double b) { return Chain(a.v + b, 1.0, a); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator+(double a, const Dual<N, M>& b) { return Chain(a + b.v, 1.0, b); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator-(const Dual<N, M>& a, double b) { return Chain(a.v - b, 1.0, a); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator-(double a, const Dual<N, M>& b) { return Chain(a - b.v, -1.0, b); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator*(double a, const Dual<N, M>& b) { return Chain(a * b.v, a, b); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator*(const Dual<N, M>& a, double b) { return Chain(a.v * b, b, a); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator/(const Dual<N, M>& a, double b) { return Chain(a.v / b, 1.0 / b, a); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> operator/(double a, const Dual<N, M>& b) {
  const double r = a / b.v;
  Dual<N, M> q;
  q.v = r;
  HC_UNROLL
  for (int k = 0; k < N; ++k)
    if (Has(M, k)) q.d[k] = -(r * b.d[k]) / b.v;
  return q;
}

// the constant v as a number of x's type
HC_HD HC_INLINE double Like(double, double v) { return v; }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Like(const Dual<N, M>&, double v) { return Widen<Dual<N, M>>::From(v); }
HC_HD HC_INLINE double Value(double x) { return x; }
template <int N, unsigned M>
HC_HD HC_INLINE double Value(const Dual<N, M>& x) { return x.v; }
HC_HD HC_INLINE double Sqrt(double x) { return std::sqrt(x); }
HC_HD HC_INLINE double Exp(double x) { return std::exp(x); }
HC_HD HC_INLINE double Pow(double x, double y) { return std::pow(x, y); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Sqrt(const Dual<N, M>& x) {
  const double r = std::sqrt(x.v);
  return Chain(r, 0.5 / r, x);
}
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Exp(const Dual<N, M>& x) {
  const double e = std::exp(x.v);
  return Chain(e, e, x);
}
// x^y, y a constant: y x^(y - 1) dx
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Pow(const Dual<N, M>& x, double y) {
  return Chain(std::pow(x.v, y), y * std::pow(x.v, y - 1.0), x);
}
// x^y (x > 0): y x^(y - 1) dx + log(x) x^y dy
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> Pow(const Dual<N, A>& x, const Dual<N, B>& y) {
  const double v = std::pow(x.v, y.v);
  return Chain(v, y.v * std::pow(x.v, y.v - 1.0), x, std::log(x.v) * v, y);
}
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Pow(double x, const Dual<N, M>& y) {
  const double r = std::pow(x, y.v);
  return Chain(r, std::log(x) * r, y);
}

// |x| (slope +1 at 0, as JAX's rule for abs)
HC_HD HC_INLINE double Abs(double x) { return std::fabs(x); }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> Abs(const Dual<N, M>& x) { return Chain(std::fabs(x.v), x.v >= 0.0 ? 1.0 : -1.0, x); }

// sign(s) k as copysign(k, s) (one instruction; a k of 0 keeps s's sign): the derivatives
// sign(s) dk, sign(0) = 0 (JAX's rule for sign(s) k; s's own derivative is 0 almost everywhere)
// (sign(s) itself as copysign([s != 0], s), and max's slope below as a sum of two masks: no
// chain of selects, fewer instructions in the tangent runs' friction kicks)
template <class S>
HC_HD HC_INLINE double CopySign(double k, const S& s) { return std::copysign(k, Value(s)); }
template <int N, unsigned M, class S>
HC_HD HC_INLINE Dual<N, M> CopySign(const Dual<N, M>& k, const S& s) {
  const double sv = Value(s), sign = std::copysign(sv != 0.0 ? 1.0 : 0.0, sv);
  return Chain(std::copysign(k.v, sv), sign, k);
}

// max(s, 0) (JAX's rule for maximum: slope 1/2 at the tie)
HC_HD HC_INLINE double MaxZero(double s) { return s > 0.0 ? s : 0.0; }
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> MaxZero(const Dual<N, M>& s) {
  return Chain(s.v > 0.0 ? s.v : 0.0, (s.v > 0.0 ? 1.0 : 0.0) + (s.v == 0.0 ? 0.5 : 0.0), s);
}

// max(a, b) (JAX's rule for maximum: at the tie half of each's derivative)
HC_HD HC_INLINE double Max(double a, double b) { return b > a ? b : a; }
template <int N, unsigned A, unsigned B>
HC_HD HC_INLINE Dual<N, A | B> Max(const Dual<N, A>& a, const Dual<N, B>& b) {
  const double wa = b.v > a.v ? 0.0 : b.v == a.v ? 0.5 : 1.0, wb = b.v > a.v ? 1.0 : b.v == a.v ? 0.5 : 0.0;
  return Chain(b.v > a.v ? b.v : a.v, wa, a, wb, b);
}

// ---------------------------------------------------------------------------------------
// The laws.

// delta_+ = where(delta > 0, delta, 0), m
template <class T>
HC_HD HC_INLINE T PositivePart(const T& overlap) {
  return Value(overlap) > 0.0 ? overlap : Like(overlap, 0.0);
}

// sqrt(delta_+) of a positive part delta_+ >= 0, m^0.5 (JAX's rule for sqrt in contact; out
// of contact delta_+ = 0 has no derivative to carry)
HC_HD HC_INLINE double RootOfPositive(double positive) {
#if HC_BRANCH_ON_CONTACT
  if (positive > 0.0) return std::sqrt(positive);
  return 0.0;
#else
  return std::sqrt(positive);
#endif
}
template <int N, unsigned M>
HC_HD HC_INLINE Dual<N, M> RootOfPositive(const Dual<N, M>& positive) {
  const double r = RootOfPositive(positive.v);
  return Chain(r, positive.v > 0.0 ? 0.5 / r : 0.0, positive);
}

// contact.hertz_force: kappa delta_+ sqrt(delta_+), then (kSprings) + spring delta, N
template <bool kSprings, class T>
HC_HD HC_INLINE T ElasticForce(const T& overlap, const T& kappa, const T& spring) {
  const T positive = PositivePart(overlap);
  T force = kappa * positive * RootOfPositive(positive);
  if (kSprings) force = force + spring * overlap;
  return force;
}

// The elastic force of a full step's contact, N, at overlap delta_+ = `positive` with root
// sqrt(delta_+) = `root`: Hertz's (kappa delta_+) sqrt(delta_+)
template <class K, class P, class R>
HC_HD HC_INLINE auto HertzElastic(const K& kappa, const P& positive, const R& root) {
  return (kappa * positive) * root;
}

// contact.power_law_force: kappa r^1.5 (delta / r)^n in contact (delta > 0), else 0, N
// (exponent n, reference overlap r, m; out of contact the ratio is 1, the double `where` of
// `contact`)
template <class O, class K, class E, class R>
HC_HD HC_INLINE auto PowerLawForce(const O& overlap, const K& kappa, const E& n, const R& r) {
  const bool in = Value(overlap) > 0.0;
  const auto ratio = Select(in, overlap / r, 1.0);
  const auto force = kappa * Pow(r, 1.5) * Pow(ratio, n);
  return Select(in, force, 0.0);
}

// An elastic-plastic contact's force along its unloading curve (`Unloading`: residual
// overlap `residual`, m, stiffness `kappa`): Hertz's about the residual overlap, N
template <class O, class Q, class K>
HC_HD HC_INLINE auto UnloadingForce(const O& overlap, const Q& residual, const K& kappa) {
  const auto positive = PositivePart(overlap - residual);
  return kappa * positive * RootOfPositive(positive);
}

// contact.track_friction_kick: sign(w) max(|w| - loss, 0), m/s
template <class W, class L>
HC_HD HC_INLINE auto Kick(const W& w, const L& loss) {
  return CopySign(MaxZero(Abs(w) - loss), w);
}

// The dashpot a contact applies (`contact.contact_force`): none where there is no contact
// law (kappa = 0: a free end, a sensor spring), N s/m.
template <class K, class D>
HC_HD HC_INLINE D ContactDashpot(const K& kappa, const D& dashpot) {
  return Value(kappa) > 0.0 ? dashpot : Like(dashpot, 0.0);
}

// The coefficient of the rate slot's law per unit overlap rate, its force being that times
// the rate (`laws.registry`: the slot's law is chosen by the library): a linear dashpot's
// gamma (N s/m), or in HC_VELOCITY_SQUARED_LIBRARY velocity-squared dissipation's c |rate|
// (`laws.VelocitySquared`, c in N s^2/m^2).
template <class D, class V>
HC_HD HC_INLINE auto RateSlotCoefficient(const D& coefficient, const V& rate) {
#if defined(HC_VELOCITY_SQUARED_LIBRARY)
  return coefficient * Abs(rate);
#else
  (void)rate;
  return coefficient;
#endif
}

// contact.contact_force (the total, clipped at 0 in contact: Kuwabara-Kono damping with
// kv = 1.5 eta kappa, and with kDashpot the rate slot's law of coefficient `dash` =
// `ContactDashpot`, `RateSlotCoefficient`) about a
// given elastic force (`elastic`, N) at overlap dl (m; root sqrt(dl_+) `rt`) and rate (m/s),
// plus the spring (kExtras), N. Branch-free (selects only): sqrt(0) = 0 is the root out of
// contact, as `contact` has it, where elastic = viscous = 0; a dashpot would push there, so
// with one the total is also 0 out of contact. kDashpot is a compile-time switch: its terms
// cost every damped run about 17 %
// (`benchmarks/results/dashpot_kernel/history/dashpot_in_cpp_kernel_not_kept.md`), so only
// the runs that have a dashpot carry them.
template <bool kViscous, bool kDashpot, class E, class R, class O, class V, class Kv, class D>
HC_HD HC_INLINE auto ClippedTotal(const E& elastic, const R& rt, const O& dl, const V& rate, const Kv& kv,
                                  const D& dash) {
  if constexpr (kViscous && kDashpot) {
    const auto s = elastic + (kv * rt + RateSlotCoefficient(dash, rate)) * rate;
    return Select(Value(dl) > 0.0, MaxZero(s), 0.0);
  } else if constexpr (kViscous) {
    return MaxZero(elastic + (kv * rt) * rate);
  } else {
    return elastic;
  }
}

template <bool kViscous, bool kExtras, bool kDashpot, class E, class R, class O, class V, class Kv, class D,
          class S>
HC_HD HC_INLINE auto DampedTotal(const E& elastic, const R& rt, const O& dl, const V& rate, const Kv& kv,
                                 const D& dash, const S& sp) {
  if constexpr (kExtras) {
    return ClippedTotal<kViscous, kDashpot>(elastic, rt, dl, rate, kv, dash) + sp * dl;  // (a spring of 0 adds nothing)
  } else {
    return ClippedTotal<kViscous, kDashpot>(elastic, rt, dl, rate, kv, dash);
  }
}

// `DampedTotal` about Hertz's elastic force
template <bool kViscous, bool kExtras, bool kDashpot, class O, class V, class K, class Kv, class D, class S>
HC_HD HC_INLINE auto TotalForce(const O& dl, const V& rate, const K& k, const Kv& kv, const D& dash, const S& sp) {
  const auto positive = PositivePart(dl);
  const auto rt = RootOfPositive(positive);
  return DampedTotal<kViscous, kExtras, kDashpot>(HertzElastic(k, positive, rt), rt, dl, rate, kv, dash, sp);
}

// ---------------------------------------------------------------------------------------
// Elastic-plastic contacts. Both laws of `contact` unload (and reload below the largest
// overlap so far, `peak`) along a Hertz curve about a residual overlap: force
// kp (delta - residual)_+^{3/2}, with (residual, kp) functions of the peak and the contact's
// constants alone (`Unloading`). Below first yield residual = 0 and kp = kappa: Hertz, to the
// bit. The kernels compute the pair when the peak grows, and the force every step from it
// (`UnloadingForce`).

// The unloading curve of an elastic-plastic contact: its residual overlap (m) and stiffness
// (N/m^{3/2}).
template <class T>
struct Unloading {
  T residual, kappa;
};

// contact.overlap_at_force: (F / kappa)^{2/3} for F > 0, else 0, m
template <class T>
HC_HD HC_INLINE T HertzOverlap(const T& force, const T& kappa) {
  return Value(force) > 0.0 ? Pow(force / kappa, 2.0 / 3.0) : 0.0 * force;
}

// contact.thornton_contact's unloading curve after the largest overlap `peak` (m), with
// Hertz stiffness `kappa` and yield force `yield_force` (N, finite)
template <class T>
HC_HD HC_INLINE Unloading<T> ThorntonUnloading(const T& peak, const T& kappa, const T& yield_force) {
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
HC_HD HC_INLINE T JgLoadingRatio(const T& ratio, const T& c, const T& hardness) {
  const T elastic = Exp(-0.25 * Pow(ratio, 5.0 / 12.0)) * Pow(ratio, 1.5);
  const T plastic = 4.0 * hardness / c * (1.0 - Exp(-1.0 * Pow(ratio, 5.0 / 9.0) / 25.0)) * ratio;
  return elastic + plastic;
}

// contact.jackson_green_contact's unloading curve after the largest overlap `peak` (m):
// Hertz stiffness `kappa`, reduced radius `radius` (m), yield stress `stress` (Pa), Poisson
// ratio `poisson`, hardness ratio `hardness`
template <class T>
HC_HD HC_INLINE Unloading<T> JacksonGreenUnloading(const T& peak, const T& kappa, const T& radius, const T& stress,
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
