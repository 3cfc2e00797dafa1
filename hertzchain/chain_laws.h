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

namespace hertzchain {

// contact.hertz_force: kappa delta_+ sqrt(delta_+), then (kSprings) + spring delta, N
template <bool kSprings>
HC_HD inline double ElasticForce(double overlap, double kappa, double spring) {
  double positive = overlap > 0.0 ? overlap : 0.0;
  double force = kappa * positive * std::sqrt(positive);
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

// sign(w) as JAX's sign gives it (0 at 0), in two selects (no branches: loops over lanes
// vectorise whatever their length)
HC_HD inline double Sign(double w) {
  double negative = w < 0.0 ? -1.0 : 0.0;
  return w > 0.0 ? 1.0 : negative;
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
// (the slope of |w|, +1 at 0) and g = sign(w) max'(s), d kick = (pm t_w - t_loss) g (g is 0,
// +-1/2 or +-1: the product is the rules' to the bit).
HC_HD inline void KickSlope(double w, double s, double* pm, double* g) {
  *pm = w >= 0.0 ? 1.0 : -1.0;
  *g = Sign(w) * MaxSlope(s);
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
// damped run about 17 % (`benchmarks/results/dashpot_in_cpp_kernel_not_kept.md`), so only
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
  double rt = std::sqrt(positive);
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

// The tangent of `TotalForce` (kExtras) along one direction: c1 = 1.5 eta, c2 = c1 kappa,
// sp the spring, tdl / trate / tk / t15e (= 1.5 t_eta) / tdash (`ContactDashpot`'s, read
// with kDashpot only) / tsp the inputs' tangents.
// `TangentForce` about the elastic force's tangent `telastic` (any law).
template <bool kViscous, bool kDashpot>
HC_HD inline double TangentTotal(const Linearisation& l, double telastic, double k, double c1, double c2, double sp,
                                 double tdl, double trate, double tk, double t15e, double tdash, double tsp) {
  double troot = tdl * l.half_inv_root;
  double tf = telastic;
  if (kViscous) {
    double tc3 = (t15e * k + c1 * tk) * l.root + c2 * troot;
    if (kDashpot) tc3 = tc3 + tdash;
    tf = (telastic + (tc3 * l.rate + l.c3 * trate)) * l.slope;
  }
  return tf + (tsp * l.delta + sp * tdl);
}

template <bool kViscous, bool kDashpot>
HC_HD inline double TangentForce(const Linearisation& l, double k, double c1, double c2, double sp, double tdl,
                                 double trate, double tk, double t15e, double tdash, double tsp) {
  double tpositive = tdl * l.in;
  double troot = tdl * l.half_inv_root;
  double telastic = (tk * l.positive + k * tpositive) * l.root + l.kp * troot;
  return TangentTotal<kViscous, kDashpot>(l, telastic, k, c1, c2, sp, tdl, trate, tk, t15e, tdash, tsp);
}

}  // namespace hertzchain
