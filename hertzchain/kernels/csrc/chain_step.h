// The phases of the full step (`chain_full_block.h`'s `FullBlock`), in the order
// `chain_kernel.cc`'s `RunFullBlock` runs them, each always inlined into that loop: the
// sensors' drift, body 0's half kick and drift, per contact the growth of its largest overlap
// (elastic-plastic laws), the sweep (drift of the next body, the contact's force, the kick of
// this body, the books) and its tangent pass, the wall's kick, the sensors' kick, and at a
// sample's end the recorded channels. The laws are `chain_laws.h`'s, on doubles for the
// values and on dual numbers for the partial derivatives the tangent passes read; the drift
// and kicks are `chain_verlet.h`'s, run on the tangents with the friction kick's
// linearisation; the compliant sensors' laws run on dual numbers along each direction.
#pragma once

#include <algorithm>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "chain_full_block.h"
#include "chain_lanes.h"
#include "chain_laws.h"
#include "chain_verlet.h"

namespace hertzchain {

// ---------------------------------------------------------------------------------------
// The laws as the step applies them.

// The friction kick's linearisation for the tangent passes, which run `chain_verlet.h`'s
// phases on tangents: t -> by_w t + by_loss t_loss, with the partials by the velocity and the
// loss that `FrictionKick` left and the loss's tangent t_loss; the identity without friction.
template <bool kFriction>
HC_LANES inline auto LinearisedKick(double by_w, double by_loss, double t_loss) {
  return [=](double t) HC_LANES {
    if constexpr (kFriction) {
      return by_w * t + by_loss * t_loss;
    } else {
      return t;
    }
  };
}

// contact.track_friction_kick with its partial derivatives by the velocity and the loss (the
// law run on dual numbers)
template <class C>
HC_LANES inline double FullBlock<C>::KickWithPartials(double w, double loss_j, double* by_w, double* by_loss) {
  const auto kicked = hertzchain::Kick(hertzchain::Seed<2, 0>(w), hertzchain::Seed<2, 1>(loss_j));
  *by_w = hertzchain::Slope(kicked, 0);
  *by_loss = hertzchain::Slope(kicked, 1);
  return kicked.v;
}

// The friction kick of a velocity w (m/s) by the lane's loss (m/s): `Kick`, with kTangent
// its partials by w and by the loss into by_w, by_loss; w itself without friction
template <class C>
HC_LANES inline double FullBlock<C>::FrictionKick(double w, double loss_j, double* by_w, double* by_loss) {
  if constexpr (!kFriction) {
    return w;
  } else if constexpr (kTangent) {
    return KickWithPartials(w, loss_j, by_w, by_loss);
  } else {
    return KickOf(w, loss_j);
  }
}

// The force of a contact with the chain's law (`contact.contact_force`: `DampedTotal` about
// Hertz's elastic force, with kPower the power law's, with kPlastic Hertz's about the
// unloading curve): at overlap dl, rate, kappa k, 1.5 eta kappa kv (computed once per block
// as JAX rounds it: (1.5 eta) kappa), dashpot d (`ContactDashpot`), spring and the law's
// two inputs (`kLawIn`); `elastic`, where given, receives the law's elastic force (the
// books read it). Any number types: doubles for the values, duals for the partials.
template <class C>
template <class O, class R, class K, class Kv, class Dd, class S, class L0, class L1>
HC_LANES inline auto FullBlock<C>::LawForce(const O& dl, const R& rate, const K& k, const Kv& kv, const Dd& d,
                                            const S& spring, const L0& law0, const L1& law1, double* elastic) {
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
  return hertzchain::DampedTotal<kViscous, kExtras, kDashpot>(own, rt, dl, rate, kv, d, spring);
}

// the law's two inputs of contact index c, lane j (kPower: the chain's exponent and
// reference overlap; kPlastic: the contact's unloading curve; Hertz's law reads none)
template <class C>
HC_LANES inline double FullBlock<C>::LawIn(int64_t c, int64_t j, int which) const {
  if constexpr (kPlastic) return which == 0 ? res[c] : kpl[c];
  if constexpr (kPower) return law[which * kLanes + j];
  return 0.0;
}

// The force of contact index c at lane j and its partial derivatives by its inputs
// (`kForceInputs`, into `slopes[q * stride]`): `LawForce` run on dual numbers seeded with
// each input, kappa and the spring only with kOwn (they have tangents in this block,
// `fixed_inputs`); c1j the lane's 1.5 eta, dash_j its chain's dashpot.
template <class C>
template <bool kOwn>
HC_LANES inline double FullBlock<C>::ContactSlopes(double dl, double rate, double k, double c1j, double dash_j,
                                                   double sp_j, int64_t c, int64_t j, double* slopes,
                                                   int64_t stride) const {
  constexpr int N = kForceInputs;
  using hertzchain::SeedIf;
  const auto kd = SeedIf<kOwn, N, kKappaIn>(k);
  const auto c1d = SeedIf<kViscous, N, kEtaIn>(c1j);
  const auto total = LawForce(hertzchain::Seed<N, kOverlapIn>(dl), SeedIf<kViscous, N, kRateIn>(rate), kd, c1d * kd,
                              hertzchain::ContactDashpot(kd, SeedIf<kDashpot, N, kDashIn>(dash_j)),
                              SeedIf<kExtras && kOwn, N, kSpringIn>(sp_j),
                              SeedIf<kPower || kPlastic, N, kLawIn>(LawIn(c, j, 0)),
                              SeedIf<kPower || kPlastic, N, kLawIn + 1>(LawIn(c, j, 1)), nullptr);
  // the partials `ForceTangent` reads: those by the seeded inputs
  constexpr unsigned kSeeded = 1u << kOverlapIn | (kOwn ? 1u << kKappaIn : 0u) |
                               (kViscous ? 1u << kRateIn | 1u << kEtaIn : 0u) | (kDashpot ? 1u << kDashIn : 0u) |
                               (kExtras && kOwn ? 1u << kSpringIn : 0u) | (kPower || kPlastic ? 3u << kLawIn : 0u);
  HC_UNROLL
  for (int q = 0; q < N; ++q)
    if (hertzchain::Has(kSeeded, q)) slopes[q * stride] = hertzchain::Slope(total, q);
  return total.v;
}

// The tangent of a contact's force along one direction from its partials (`slopes[q *
// stride]`) and its inputs' tangents: tdl, trate, tk, t15e (1.5 eta's), tdash_q (the chain's
// dashpot's), tsp, tlaw0, tlaw1; kST: whether kappa's and the spring's tangents `tk`, `tsp`
// can be other than 0 (`ContactSlopes`' kOwn)
template <class C>
template <bool kST>
HC_LANES inline double FullBlock<C>::ForceTangent(const double* slopes, int64_t stride, double tdl, double trate,
                                                  double tk, double t15e, double tdash_q, double tsp, double tlaw0,
                                                  double tlaw1) const {
  double t = slopes[kOverlapIn * stride] * tdl;
  if constexpr (kST) t = t + slopes[kKappaIn * stride] * tk;
  if constexpr (kViscous) t = t + slopes[kRateIn * stride] * trate + slopes[kEtaIn * stride] * t15e;
  if constexpr (kDashpot) t = t + slopes[kDashIn * stride] * tdash_q;
  if constexpr (kExtras && kST) t = t + slopes[kSpringIn * stride] * tsp;
  if constexpr (kPower || kPlastic) t = t + slopes[kLawIn * stride] * tlaw0 + slopes[(kLawIn + 1) * stride] * tlaw1;
  return t;
}

// the tangents of the law's two inputs of contact i, lane j, along direction d (kPlastic:
// the residual overlap's and the stiffness's, through the unloading curve's partials by
// the peak, kappa and the law's inputs; kPower: the exponent's and the reference's)
template <class C>
HC_LANES inline void FullBlock<C>::LawTangents(int64_t i, int64_t j, int64_t d, double* tlaw0, double* tlaw1) const {
  *tlaw0 = *tlaw1 = 0.0;
  if constexpr (kPlastic) {
    for (int q = 0; q < kInputs; ++q) {
      const double t = PlasticInput(q, d, i, j);
      *tlaw0 = *tlaw0 + dres[q * plastic_size + i * kLanes + j] * t;
      *tlaw1 = *tlaw1 + dkpl[q * plastic_size + i * kLanes + j] * t;
    }
  } else if constexpr (kPower) {
    *tlaw0 = tlaw[d * 2 * kLanes + j];
    *tlaw1 = tlaw[(d * 2 + 1) * kLanes + j];
  }
}

// the unloading curve of contact i, lane j (and its partials) at its peak
template <class C>
inline void FullBlock<C>::Unload(int64_t i, int64_t j) {
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
    in[2] = law[(contacts + i) * kLanes + j];      // reduced radius
    in[3] = law[3 * contacts * kLanes + j];        // yield stress
    in[4] = law[(2 * contacts + i) * kLanes + j];  // Poisson ratio
    in[5] = law[(3 * contacts + 1) * kLanes + j];  // hardness ratio
  }
  const hertzchain::Unloading<double> u = PlasticCurve<kLaw>(in, kTangent ? slopes : nullptr);
  res[c] = u.residual;
  kpl[c] = u.kappa;
  if constexpr (kTangent)
    for (int k = 0; k < kInputs; ++k) {
      dres[k * plastic_size + c] = slopes[k];
      dkpl[k * plastic_size + c] = slopes[kInputs + k];
    }
}

// the tangent of input k of contact i, lane j, along direction d (`kInputs`' order)
template <class C>
inline double FullBlock<C>::PlasticInput(int k, int64_t d, int64_t i, int64_t j) const {
  if (k == 0) return tpk[(d * contacts + i) * kLanes + j];
  if (k == 1) return tkap[(d * contacts + i) * kLanes + j];
  const double* t = &tlaw[d * law_rows * kLanes];
  if constexpr (kLaw == Law::kThornton) return t[i * kLanes + j];  // the yield force
  if (k == 2) return t[(contacts + i) * kLanes + j];                // reduced radius
  if (k == 3) return t[3 * contacts * kLanes + j];                  // yield stress
  if (k == 4) return t[(2 * contacts + i) * kLanes + j];            // Poisson ratio
  return t[(3 * contacts + 1) * kLanes + j];                        // hardness ratio
}

// ---------------------------------------------------------------------------------------
// The compliant sensors' laws (`compliant_sensor`), over the number type: doubles for the
// values, a dual number along one direction (`hertzchain::Along`) for each direction's
// tangents.

// A value and its tangent along one direction as a dual number.
HC_LANES inline hertzchain::Dual<1, 1u> WithTangent(double value, double tangent) {
  return hertzchain::Along(value, tangent);
}

// A sensor's first half kick and drift (`compliant_sensor.drift`): from its drive, force and
// rate (N, N/s) and its 1/omega0^2 (s^2; `quasi`: the step does not resolve its resonance,
// and the force follows the drive), its new force, half-step rate and predicted rate.
template <class T>
struct SensorDrifted {
  T force, half, predicted;
};
template <class T>
HC_LANES inline SensorDrifted<T> SensorDriftOf(const T& drive, const T& force, const T& rate, const T& inv_w2,
                                               bool quasi, double h, double dt) {
  const T gap = drive - force;
  const T accel = quasi ? hertzchain::Like(gap, 0.0) : gap / inv_w2;
  const T half = rate + h * accel;
  return {quasi ? drive : force + dt * half, half, half + h * accel};
}

// A sensor's second half kick (`compliant_sensor.kick`) from its new drive beta F_back +
// (1 - beta) F_front: the drive and the new rate (0 where `quasi`).
template <class T>
struct SensorKicked {
  T drive, rate;
};
template <class T>
HC_LANES inline SensorKicked<T> SensorKickOf(const T& beta, const T& back, const T& front, const T& force,
                                             const T& half, const T& inv_w2, bool quasi, double h) {
  const T drive = beta * back + (1.0 - beta) * front;
  const T gap = drive - force;
  const T accel = quasi ? hertzchain::Like(gap, 0.0) : gap / inv_w2;
  return {drive, quasi ? hertzchain::Like(gap, 0.0) : half + h * accel};
}

// ---------------------------------------------------------------------------------------
// The phases of a step.

// The sensors' first half kick and drift (`compliant_sensor.drift`), then the cuts of every
// sensor's back (row K - 1) and front (row K) contacts: zeroed, then the backs' terms, then
// the fronts' (the order of `compliant_sensor.shortened`)
template <class C>
HC_LANES inline void FullBlock<C>::SensorDrift(StepSize t, Lanes& __restrict l) {
  const double h = t.h, dt = t.dt;
  if constexpr (kSensors) {
    for (int64_t k = 0; k < ns; ++k)
      for (int64_t j = 0; j < kLanes; ++j) {
        const int64_t c = k * kLanes + j;
        const double inv_w2 = sp[inv_row(k) * kLanes + j], first = sp[first_row * kLanes + j];
        const bool quasi = inv_w2 < t.dt2;  // the step does not resolve the resonance
        if constexpr (kTangent)  // (before the values move on: the same law on dual numbers)
          for (int64_t d = 0; d < D; ++d) {
            const int64_t q = (d * ns + k) * kLanes + j;
            const auto drifted = SensorDriftOf(WithTangent(sd[c], tsd[q]), WithTangent(sf[c], tsf[q]),
                                               WithTangent(sr[c], tsr[q]),
                                               WithTangent(inv_w2, tsens(d, inv_row(k))[j]), quasi, h, dt);
            tsf[q] = drifted.force.d[0];
            ts_half[q] = drifted.half.d[0];
            ts_pred[q] = drifted.predicted.d[0];
            ts_amt[q] = (drifted.force - WithTangent(first, tsens(d, first_row)[j])).d[0];
          }
        const SensorDrifted<double> drifted = SensorDriftOf(sd[c], sf[c], sr[c], inv_w2, quasi, h, dt);
        sf[c] = drifted.force;
        s_half[c] = drifted.half;
        s_pred[c] = drifted.predicted;
        s_amt[c] = drifted.force - first;
        s_quasi[c] = quasi ? 1.0 : 0.0;
      }
    for (int64_t k = 0; k < ns; ++k)
      for (const int64_t row : {beads[k] - 1, beads[k]})
        for (int64_t j = 0; j < kLanes; ++j) {
          cut[row * kLanes + j] = cut_rate[row * kLanes + j] = 0.0;
          for (int64_t d = 0; d < D; ++d)
            tcut[(d * contacts + row) * kLanes + j] = tcut_rate[(d * contacts + row) * kLanes + j] = 0.0;
        }
    for (const int64_t side : {0, 1})  // 0: the sensors' back contacts, 1: their front ones
      for (int64_t k = 0; k < ns; ++k) {
        const int64_t row = beads[k] - 1 + side, crow = side == 0 ? back_row(k) : front_row(k);
        for (int64_t j = 0; j < kLanes; ++j) {
          const int64_t e = k * kLanes + j, i = row * kLanes + j;
          const double comp = sp[crow * kLanes + j];
          // the contact shortened by the sensor's compliance times its force (or rate)
          const auto shortened = [](const auto& cut_by, const auto& compliance, const auto& amount) HC_LANES {
            return cut_by - compliance * amount;
          };
          for (int64_t d = 0; d < D; ++d) {  // (the same on dual numbers)
            const int64_t td = (d * contacts + row) * kLanes + j, te = (d * ns + k) * kLanes + j;
            const auto tcomp = WithTangent(comp, tsens(d, crow)[j]);
            tcut[td] = shortened(WithTangent(cut[i], tcut[td]), tcomp, WithTangent(s_amt[e], ts_amt[te])).d[0];
            tcut_rate[td] =
                shortened(WithTangent(cut_rate[i], tcut_rate[td]), tcomp, WithTangent(s_pred[e], ts_pred[te])).d[0];
          }
          cut[i] = shortened(cut[i], comp, s_amt[e]);
          cut_rate[i] = shortened(cut_rate[i], comp, s_pred[e]);
        }
      }
  }
}

// body 0: half kick, friction, drift, predicted velocity (and their tangents)
template <class C>
HC_LANES inline void FullBlock<C>::FirstBody(StepSize t, Lanes& __restrict l) {
  const double h = t.h, dt = t.dt;
  for (int64_t j = 0; j < kLanes; ++j) {
    if constexpr (kBooks) l.work1[j] = l.work2[j] = l.lost1[j] = l.lost2[j] = l.d_prev[j] = 0.0;
    auto kick = [&](double raw) HC_LANES {
      if constexpr (kBooks) l.raw_prev[j] = raw;
      return FrictionKick(raw, l.loss[j], &l.kick1_w[j], &l.kick1_loss[j]);
    };
    double position = x[j], predicted;
    const double w = HalfKickAndDrift(v[j], a[j], h, dt, kick, position, predicted);
    x[j] = position;
    l.w_prev[j] = w;
    l.p_prev[j] = predicted;
    l.f_prev[j] = 0.0;
  }
  if (kTangent)
    for (int64_t d = 0; d < D; ++d)
      ForLanes<kLanes>([&](int64_t j) HC_LANES {
        const int64_t q = d * kLanes + j, row = d * rows_x * kLanes + j;
        double position = tx[row], predicted;
        const double tw = HalfKickAndDrift(tv[row], ta[row], h, dt,
                                           LinearisedKick<kFriction>(l.kick1_w[j], l.kick1_loss[j], tloss[q]),
                                           position, predicted);
        tx[row] = position;
        tw_prev[q] = tw;
        tp_prev[q] = predicted;
        tf_prev[q] = 0.0;
      });
}

// kPlastic: contact i's largest overlap so far, with this step's (`batched_step._step`), before
// the sweep: the overlap from body i + 1's drift as the sweep computes it (the same
// operations, so the same bits), then the unloading curve of the lanes whose overlap grew.
// The sweep itself then has no branch and vectorises.
template <class C>
HC_LANES inline void FullBlock<C>::GrowPeaks(int64_t i, StepSize t, Lanes& __restrict l) {
  const double h = t.h, dt = t.dt;
  const int64_t ri = i * kLanes, rn = (i + 1) * kLanes;
  bool grown = false;
  ForLanes<kLanes>([&](int64_t j) HC_LANES {
    double drifted = x[rn + j], predicted;
    HalfKickAndDrift(v[rn + j], a[rn + j], h, dt, [&](double w) HC_LANES { return kFriction ? KickOf(w, l.loss[j]) : w; },
                     drifted, predicted);
    double dl = x[ri + j] - drifted;
    if constexpr (kExtras) dl = dl + ov0[ri + j];
    if constexpr (kSensors) dl = dl + cut[ri + j];
    const double old = pk[ri + j];
    if constexpr (kTangent) {
      const auto peak = hertzchain::Max(hertzchain::Seed<2, 0>(old), hertzchain::Seed<2, 1>(dl));
      l.peak_by_old[j] = hertzchain::Slope(peak, 0);
      l.peak_by_overlap[j] = hertzchain::Slope(peak, 1);
    }
    l.fresh[j] = dl > old && yields[ri + j] != 0.0 ? 1.0 : 0.0;
    pk[ri + j] = hertzchain::Max(old, dl);
    grown = grown || l.fresh[j] != 0.0;
  });
  if (grown)
    for (int64_t j = 0; j < kLanes; ++j)
      if (l.fresh[j] != 0.0) Unload(i, j);
}

// Contact i's sweep over the lanes: body i + 1's half kick, friction, drift and predicted
// velocity, contact i's force (kTangent: with its partials), body i's second half kick and
// friction, the books; then (kSensors) contact i's total force, a sensor's next drive.
// kUK / kUM: kappa and 1.5 eta kappa / the inverse mass of body i are one value for every
// lane of the row (read once: the same numbers); kOwn: `ContactSlopes`'.
template <class C>
template <bool kUK, bool kUM, bool kOwn>
HC_LANES inline void FullBlock<C>::Sweep(int64_t i, StepSize t, Lanes& __restrict l) {
  const double h = t.h, dt = t.dt;
  const int64_t ri = i * kLanes, rn = (i + 1) * kLanes;
  const double k0 = kap[ri], kv0 = kvis[ri], d0 = kDashpot ? dsh[ri] : 0.0, m0 = inv[ri];
  ForLanes<kLanes>([&](int64_t j) HC_LANES {
    const double kj = kUK ? k0 : kap[ri + j], kvj = kUK ? kv0 : kvis[ri + j];
    const double dj = kDashpot ? (kUK ? d0 : dsh[ri + j]) : 0.0;
    // body i + 1: half kick, friction, drift, predicted velocity
    double w_raw;
    auto first_kick = [&](double raw) HC_LANES {
      w_raw = raw;
      return FrictionKick(raw, l.loss[j], &l.kick1_w[j], &l.kick1_loss[j]);
    };
    double position = x[rn + j], pred;
    const double w = HalfKickAndDrift(v[rn + j], a[rn + j], h, dt, first_kick, position, pred);
    x[rn + j] = position;
    // contact i
    double dl = x[ri + j] - x[rn + j];
    if constexpr (kExtras) dl = dl + ov0[ri + j];
    double rt_rate = l.p_prev[j] - pred;
    if constexpr (kSensors) {
      dl = dl + cut[ri + j];
      rt_rate = rt_rate + cut_rate[ri + j];
    }
    double elastic_i;
    double f;
    if constexpr (kTangent)
      f = ContactSlopes<kOwn>(dl, rt_rate, kj, l.c1[j], dash[j], spr[ri + j], ri + j, j, &l.force_slopes[j], kLanes);
    else
      f = LawForce(dl, rt_rate, kj, kvj, dj, spr[ri + j], LawIn(ri + j, j, 0), LawIn(ri + j, j, 1),
                   kBooks ? &elastic_i : nullptr);
    // body i: second half kick, friction
    double b = l.f_prev[j] - f;
    if constexpr (kExtras) b = b + ext[ri + j];
    double acc = b * (kUM ? m0 : inv[ri + j]);
    double vn_raw;
    const double vn = SecondHalfKick(l.w_prev[j], acc, h, [&](double raw) HC_LANES {
      vn_raw = raw;
      return FrictionKick(raw, l.loss[j], &l.kick2_w[j], &l.kick2_loss[j]);
    });
    if constexpr (kBooks) {  // body i's energy terms, contact i's largest force
      if (kViscous) {
        // total - elastic of contact i (springs in both, as `batched` adds them)
        double elastic = elastic_i;
        if constexpr (kExtras) elastic = elastic + spr[ri + j] * dl;
        const double di = f - elastic, viscous = l.d_prev[j] - di;
        l.work1[j] = l.work1[j] + vis[ri + j] * h * 0.5 * (v[ri + j] + l.raw_prev[j]);
        l.work2[j] = l.work2[j] + viscous * h * 0.5 * (l.w_prev[j] + vn_raw);
        vis[ri + j] = viscous;
        l.d_prev[j] = di;
      }
      if (kFriction) {
        l.lost1[j] = l.lost1[j] + mass[ri + j] * (l.raw_prev[j] * l.raw_prev[j] - l.w_prev[j] * l.w_prev[j]);
        l.lost2[j] = l.lost2[j] + mass[ri + j] * (vn_raw * vn_raw - vn * vn);
      }
      top[ri + j] = std::max(top[ri + j], f);
      l.raw_prev[j] = w_raw;
    }
    a[ri + j] = acc;
    v[ri + j] = vn;
    if constexpr (kTangent && kOwn) l.body[j] = b;  // what the tangent pass needs of this step
    l.f_prev[j] = f;
    l.w_prev[j] = w;
    l.p_prev[j] = pred;
  });
  if constexpr (kSensors) {  // contact i's total force: a sensor's next drive
    const int64_t sb = back_of[i], sf_ = front_of[i];
    if (sb >= 0) std::copy(l.f_prev, l.f_prev + kLanes, &s_fb[sb * kLanes]);
    if (sf_ >= 0) std::copy(l.f_prev, l.f_prev + kLanes, &s_ff[sf_ * kLanes]);
  }
}

// Contact i's tangent pass, direction by direction: `Sweep`'s operations on the tangents,
// from the partials it left; kFixed: the bodies' and contacts' own inputs (inverse masses,
// kappa, preload, springs, external forces) have no tangent in this block (`fixed_inputs`)
template <class C>
template <bool kFixed>
HC_LANES inline void FullBlock<C>::TangentSweep(int64_t i, StepSize t, Lanes& __restrict l) {
  const double h = t.h, dt = t.dt;
  const int64_t ri = i * kLanes;
  // kSensors: the sensor whose back (sb) and front (sf_) contact this is (-1: none)
  const int64_t sb = kSensors ? back_of[i] : -1, sf_ = kSensors ? front_of[i] : -1;
  for (int64_t d = 0; d < D; ++d) {
    const int64_t ti = (d * rows_x + i) * kLanes, tn = (d * rows_x + i + 1) * kLanes;
    const int64_t tc = (d * contacts + i) * kLanes;
    ForLanes<kLanes>([&](int64_t j) HC_LANES {
      const int64_t q = d * kLanes + j;
      double position = tx[tn + j], tpred;
      const double tw = HalfKickAndDrift(tv[tn + j], ta[tn + j], h, dt,
                                         LinearisedKick<kFriction>(l.kick1_w[j], l.kick1_loss[j], tloss[q]),
                                         position, tpred);
      tx[tn + j] = position;
      double tdl = tx[ti + j] - tx[tn + j];
      if constexpr (kExtras && !kFixed) tdl = tdl + tov0[tc + j];
      double trate = tp_prev[q] - tpred;
      if constexpr (kSensors) {
        tdl = tdl + tcut[tc + j];
        trate = trate + tcut_rate[tc + j];
      }
      if constexpr (kPlastic)  // the peak's tangent: max(peak, overlap)'s
        tpk[tc + j] = l.peak_by_old[j] * tpk[tc + j] + l.peak_by_overlap[j] * tdl;
      double tlaw0, tlaw1;
      LawTangents(i, j, d, &tlaw0, &tlaw1);
      double tf = ForceTangent<!kFixed>(&l.force_slopes[j], kLanes, tdl, trate, tkap[tc + j], t15eta[q], tdash[q],
                                        kFixed ? 0.0 : tspr[tc + j], tlaw0, tlaw1);
      double tb = tf_prev[q] - tf;
      if constexpr (kExtras && !kFixed) tb = tb + text[ti + j];
      double tacc = tb * inv[ri + j];
      if constexpr (!kFixed) tacc = tacc + l.body[j] * tinv[ti + j];
      const double tvn =
          SecondHalfKick(tw_prev[q], tacc, h, LinearisedKick<kFriction>(l.kick2_w[j], l.kick2_loss[j], tloss[q]));
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
}

// the wall's row (inverse mass 0: it stays at rest, as in the JAX kernel), with its books
// and the step's dissipation, and its tangents
template <class C>
HC_LANES inline void FullBlock<C>::Wall(StepSize t, Lanes& __restrict l) {
  const double h = t.h;
  const int64_t rw = contacts * kLanes;
  for (int64_t j = 0; j < kLanes; ++j) {
    double b = l.f_prev[j];
    if constexpr (kExtras) b = b + ext[rw + j];
    double acc = b * inv[rw + j];
    double vn_raw;
    const double vn = SecondHalfKick(l.w_prev[j], acc, h, [&](double raw) HC_LANES {
      vn_raw = raw;
      return FrictionKick(raw, l.loss[j], &l.kick2_w[j], &l.kick2_loss[j]);
    });
    if constexpr (kBooks) {  // the wall's terms, then the step's dissipation
      if (kViscous) {
        l.work1[j] = l.work1[j] + vis[rw + j] * h * 0.5 * (v[rw + j] + l.raw_prev[j]);
        l.work2[j] = l.work2[j] + l.d_prev[j] * h * 0.5 * (l.w_prev[j] + vn_raw);
        vis[rw + j] = l.d_prev[j];
      }
      const double work = l.damped[j] != 0.0 ? l.work1[j] + l.work2[j] : 0.0;
      spent[j] = (spent[j] - work) + (0.5 * l.lost1[j] + 0.5 * l.lost2[j]);
    }
    l.body[j] = b;
    a[rw + j] = acc;
    v[rw + j] = vn;
  }
  if (kTangent)
    for (int64_t d = 0; d < D; ++d)
      ForLanes<kLanes>([&](int64_t j) HC_LANES {
        const int64_t q = d * kLanes + j, tw_row = (d * rows_x + contacts) * kLanes;
        double tb = tf_prev[q];
        if constexpr (kExtras) tb = tb + text[tw_row + j];
        double tacc = tb * inv[rw + j] + l.body[j] * tinv[tw_row + j];
        const double tvn =
            SecondHalfKick(tw_prev[q], tacc, h, LinearisedKick<kFriction>(l.kick2_w[j], l.kick2_loss[j], tloss[q]));
        ta[tw_row + j] = tacc;
        tv[tw_row + j] = tvn;
      });
}

// the sensors' second half kick, from the new drive (`compliant_sensor.kick`)
template <class C>
HC_LANES inline void FullBlock<C>::SensorKick(StepSize t, Lanes& __restrict l) {
  const double h = t.h;
  if constexpr (kSensors) {
    for (int64_t k = 0; k < ns; ++k)
      for (int64_t j = 0; j < kLanes; ++j) {
        const int64_t c = k * kLanes + j;
        const double beta = sp[beta_row(k) * kLanes + j], inv_w2 = sp[inv_row(k) * kLanes + j];
        const bool quasi = s_quasi[c] != 0.0;
        if constexpr (kTangent)  // (before the values move on: the same law on dual numbers)
          for (int64_t d = 0; d < D; ++d) {
            const int64_t q = (d * ns + k) * kLanes + j;
            const auto kicked = SensorKickOf(
                WithTangent(beta, tsens(d, beta_row(k))[j]), WithTangent(s_fb[c], ts_fb[q]),
                WithTangent(s_ff[c], ts_ff[q]), WithTangent(sf[c], tsf[q]), WithTangent(s_half[c], ts_half[q]),
                WithTangent(inv_w2, tsens(d, inv_row(k))[j]), quasi, h);
            tsr[q] = kicked.rate.d[0];
            tsd[q] = kicked.drive.d[0];
          }
        const SensorKicked<double> kicked = SensorKickOf(beta, s_fb[c], s_ff[c], sf[c], s_half[c], inv_w2, quasi, h);
        sr[c] = kicked.rate;
        sd[c] = kicked.drive;
      }
  }
}

template <class C>
HC_LANES inline void FullBlock<C>::Record(Lanes& __restrict l) {
  for (int64_t c = 0; c < n_channels; ++c) {
    const int64_t i = channels[c], ri = i * kLanes, rn = (i + 1) * kLanes;
    // kSensors: the sensors' forces and rates at the sample shorten contact i
    const int64_t sb = kSensors ? back_of[i] : -1, sf_ = kSensors ? front_of[i] : -1;
    for (int64_t j = 0; j < kLanes; ++j) {
      // contact i's overlap and rate over a number type: doubles for the values (d = -1), dual
      // numbers along direction d for its tangents (`WithTangent`; `tangent` read only then)
      auto overlap_and_rate = [&](auto on_duals, int64_t d) HC_LANES {
        constexpr bool kDual = decltype(on_duals)::value;
        auto number = [&](double value, const auto& tangent) HC_LANES {
          if constexpr (kDual) {
            return WithTangent(value, tangent());
          } else {
            return value;
          }
        };
        const int64_t ti = (d * rows_x + i) * kLanes + j, tn = (d * rows_x + i + 1) * kLanes + j;
        const int64_t tc = (d * contacts + i) * kLanes + j;
        auto dl = number(x[ri + j], [&] { return tx[ti]; }) - number(x[rn + j], [&] { return tx[tn]; });
        if constexpr (kExtras) dl = dl + number(ov0[ri + j], [&] { return tov0[tc]; });
        auto rate = number(v[ri + j], [&] { return tv[ti]; }) - number(v[rn + j], [&] { return tv[tn]; });
        if constexpr (kSensors) {
          const auto first = number(sp[first_row * kLanes + j], [&] { return tsens(d, first_row)[j]; });
          auto shorten = [&](int64_t k, int64_t row) {  // by sensor k's compliance in `row`
            const auto comp = number(sp[row * kLanes + j], [&] { return tsens(d, row)[j]; });
            const int64_t e = k * kLanes + j, te = (d * ns + k) * kLanes + j;
            dl = dl - comp * (number(sf[e], [&] { return tsf[te]; }) - first);
            rate = rate - comp * number(sr[e], [&] { return tsr[te]; });
          };
          if (sb >= 0) shorten(sb, back_row(sb));
          if (sf_ >= 0) shorten(sf_, front_row(sf_));
        }
        return std::make_pair(dl, rate);
      };
      const auto [dl, rate] = overlap_and_rate(std::false_type{}, -1);
      if constexpr (!kTangent) {
        const double dj = kDashpot ? dsh[ri + j] : 0.0;
        record.slot(0, c)[j] = LawForce(dl, rate, kap[ri + j], kvis[ri + j], dj, spr[ri + j], LawIn(ri + j, j, 0),
                                        LawIn(ri + j, j, 1), nullptr);
        continue;
      }
      double here[kForceInputs];  // the force's partials (`ContactSlopes`)
      record.slot(0, c)[j] = ContactSlopes<true>(dl, rate, kap[ri + j], l.c1[j], dash[j], spr[ri + j], ri + j, j, here, 1);
      for (int64_t d = 0; d < D; ++d) {
        const int64_t q = d * kLanes + j, tc = (d * contacts + i) * kLanes;
        const auto [tdl, trate] = overlap_and_rate(std::true_type{}, d);
        double tlaw0, tlaw1;
        LawTangents(i, j, d, &tlaw0, &tlaw1);
        record.slot(d + 1, c)[j] = ForceTangent<true>(here, 1, tdl.d[0], trate.d[0], tkap[tc + j], t15eta[q],
                                                      tdash[q], tspr[tc + j], tlaw0, tlaw1);
      }
    }
  }
}

}  // namespace hertzchain
