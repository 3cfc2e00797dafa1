// The state of a block of chains through the full step of `batched_step._step` (velocities and accelerations kept apart): Kuwabara-Kono
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
// A block's state and parameters (`FullBlock`, loaded here), its step's phases (`chain_step.h`)
// and the loop that runs them (`chain_kernel.cc`'s `RunFullBlock`).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "chain_blocks.h"
#include "chain_lanes.h"
#include "chain_laws.h"

namespace hertzchain {

// The contacts' elastic law of a full run (`batched.KernelFlags.law`): each library runs one
// (the libraries without a law macro Hertz's; chain_kernel.cc's HC_LIBRARY_LAW the others').
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
__attribute__((noinline)) static hertzchain::Unloading<double> PlasticCurve(const double* in, double* slopes) {
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

// The compile-time switches of a full run (a policy type: every combination its own code):
// kLanes chains; kViscous, kFriction, kDashpot the physics; kTangent the forward-mode
// tangents; kExtras the preload's and springs' terms; kBooks the books; kLaw the contacts'
// law; kSensors the compliant sensors.
template <int64_t kLanes_, bool kViscous_, bool kFriction_, bool kTangent_, bool kExtras_, bool kDashpot_,
          bool kBooks_, Law kLaw_, bool kSensors_>
struct FullStep {
  static constexpr int64_t kLanes = kLanes_;
  static constexpr bool kViscous = kViscous_, kFriction = kFriction_, kTangent = kTangent_, kExtras = kExtras_;
  static constexpr bool kDashpot = kDashpot_, kBooks = kBooks_, kSensors = kSensors_;
  static constexpr Law kLaw = kLaw_;
};

// A block of chains through the full step (`FullStep` C): its state, parameters and tangents
// as (rows, kLanes) blocks, loaded by the constructor; the step's phases (`chain_step.h`),
// each always inlined into the loop that runs them (`RunFullBlock`), read and write them.
// A step's length dt (s), its half h and its square dt2 (s^2): passed to the phases by
// value, so that they stay in registers (read from memory, every store to a row might
// have changed them)
struct StepSize {
  double dt, h, dt2;
};

template <class C>
struct FullBlock {
  static constexpr int64_t kLanes = C::kLanes;
  static constexpr bool kViscous = C::kViscous, kFriction = C::kFriction, kTangent = C::kTangent;
  static constexpr bool kExtras = C::kExtras, kDashpot = C::kDashpot, kBooks = C::kBooks, kSensors = C::kSensors;
  static constexpr Law kLaw = C::kLaw;
  static_assert(!(kBooks && kTangent), "the books are kept by forward runs only");
  static_assert(!kSensors || !kBooks, "compliant sensors: no books");
  static constexpr bool kPower = kLaw == Law::kPower;
  static constexpr bool kPlastic = IsPlastic(kLaw);
  // kPlastic: the inputs of a contact's unloading curve (the peak, kappa, then the law's own)
  static constexpr int kInputs = kLaw == Law::kJacksonGreen ? 6 : 3;
  // The inputs of a contact's force in the tangent runs, in the order of its partial
  // derivatives (`force_slopes`): the overlap (m) and kappa, with damping the rate (m/s) and
  // 1.5 eta (s), with a dashpot the chain's dashpot (N s/m), with the extras the spring
  // (N/m), then the law's own two: the power law's exponent and reference overlap (m), an
  // elastic-plastic contact's residual overlap (m) and unloading stiffness (N/m^1.5).
  static constexpr int kOverlapIn = 0, kKappaIn = 1, kRateIn = 2, kEtaIn = 3;
  static constexpr int kDashIn = kViscous ? 4 : 2, kSpringIn = kDashIn + (kDashpot ? 1 : 0);
  static constexpr int kLawIn = kSpringIn + (kExtras ? 1 : 0);
  static constexpr int kForceInputs = kLawIn + (kPower || kPlastic ? 2 : 0);

  FullBlock(int64_t bodies, int64_t lo, int64_t batch, int64_t n_samples, int64_t steps_per_sample, double dt,
            const double* state0, const FullParams& p, const std::vector<int64_t>& channels,
            const std::vector<double*>& traces, int64_t directions, const TangentInputs& tin,
            const std::vector<double*>& ttraces, const BooksIO& books);

  // the run
  const int64_t bodies, lo, batch, n_samples, steps_per_sample;
  const std::vector<int64_t>& channels;
  const std::vector<double*>& traces;
  const std::vector<double*>& ttraces;
  const BooksIO books;
  const int64_t* beads;  // the sensors' beads K (back contact K - 1, front contact K)
  const int64_t rows_x, contacts, law_rows;
  const int64_t n_channels, D;
  const int64_t valid;  // a last, partial block repeats its last chain
  // the chains' state and parameters
  std::vector<double> x, v, a, inv, kap, ov0, spr, ext, eta, fr, dash;
  // kSensors: the compliant sensors (`compliant_sensor`, `batched_step._step`): their forces (N),
  // rates (N/s) and drives (Eq. 4, N) after x, v, a in state0 (n rows each), their
  // parameters `sp` (`SensorRows`); per step the half-step rates, the predicted rates, the
  // compressions counted from the preload's force (F_s - F_0) and whether the step resolves
  // the resonance (`compliant_sensor.drift`), and the total forces of their back and front
  // contacts (the next drive). `back_of[i]` / `front_of[i]`: the sensor whose back / front
  // contact is contact i (-1: none). `cut` / `cut_rate`: what the sensors take from every
  // contact's overlap (m) and rate (m/s) in the step (`compliant_sensor.shortened`; 0 for
  // the contacts without a sensor: adding 0 changes no bit; a contact between two sensors
  // loses the back's term, then the front's).
  const int64_t ns, sensor_rows;
  std::vector<double> sf, sr, sd, sp, s_half, s_pred, s_amt, s_quasi, s_fb, s_ff, cut, cut_rate;
  std::vector<int64_t> back_of, front_of;
  // rows of `sp` (and of its tangents, direction by direction)
  static int64_t beta_row(int64_t k) { return k; }
  int64_t inv_row(int64_t k) const { return ns + k; }
  int64_t back_row(int64_t k) const { return 2 * ns + k; }
  int64_t front_row(int64_t k) const { return 3 * ns + k; }
  const int64_t first_row;
  // kPower: every contact's law is `contact.power_law_force` of the chain's exponent (row 0)
  // and reference overlap (row 1); kPlastic: the rows of `LawRows`
  std::vector<double> law;
  // 1.5 eta kappa and (kDashpot) the dashpot (`hertzchain::ContactDashpot`) of every contact
  std::vector<double> kvis, dsh;
  // the books (kBooks): `top` the largest total force of every contact, `vis` the viscous
  // force on every body (damping), `spent` the energy dissipated, `mass` (friction)
  const int64_t peak_row, top_row, vis_row, spent_row;
  std::vector<double> top, vis, mass, spent;
  // tangents (D, rows, kLanes)
  std::vector<double> tx, tv, ta, tinv, tkap, tov0, tspr, text, teta, tfr, tdash;
  // Whether no direction moves this block's inverse masses and stiffnesses nor, with
  // kExtras, its preload's overlaps, springs or external forces (a fit of damping, friction
  // and impact speed): the sweep then seeds neither kappa nor the spring (the dual numbers
  // carry fewer partials) and its tangent pass leaves their terms out (products with 0: no
  // value changes) and reads a third fewer rows.
  bool fixed_inputs = false;
  // kSensors: the tangents of the sensors' state and parameters, (D, rows, kLanes), and of
  // the step's half-step rates, predicted rates, compressions, contact forces and cuts
  std::vector<double> tsf, tsr, tsd, tsp, ts_half, ts_pred, ts_amt, ts_fb, ts_ff, tcut, tcut_rate;
  // the sensors' tangent rows of direction d
  double* tsens(int64_t d, int64_t row) { return &tsp[(d * sensor_rows + row) * kLanes]; }
  std::vector<double> tlaw;  // (D, law_rows, kLanes)
  // kPlastic: every contact's largest overlap so far (`peak`, m; the state's with the books,
  // else the overlaps at the start, as `batched._initial_peak` has them) and the unloading
  // curve it leaves (`hertzchain::Unloading`: residual overlap `res`, stiffness `kpl`);
  // `yields` 1 where the contact's law is plastic (a finite yield force; for Jackson-Green's
  // law, and a contact law: `forces.elastic_parts`), else Hertz's. With kTangent, the partial
  // derivatives of (res, kpl) by the law's inputs (`kInputs`: the peak, kappa, then the
  // law's own, `PlasticInputs`) and the peaks' tangents (D, contacts, kLanes).
  const int64_t plastic_size;
  std::vector<double> pk, res, kpl, yields, dres, dkpl, tpk;
  // recorded sets: the forces, then (kTangent) their tangent along every direction
  SampleBuffer<kLanes> record;
  // rows whose kappa and 1.5 eta kappa, or inverse mass, are one value for every lane
  std::vector<char> uniform_k, uniform_m;

  // tangents of `Lanes`' w_prev, p_prev, f_prev and per-direction constants (D, kLanes)
  std::vector<double> tw_prev, tp_prev, tf_prev, tloss, t15eta;

  // The step's per-lane values, a local of the loop (`RunFullBlock`) passed to every phase:
  // its address never leaves the loop, so the compiler knows that no store to the block's
  // rows changes them (as the block's members, whose rows' allocations see its address, they
  // cost the tangent run of `benchmarks/native_step.py` 2.3x its instructions).
  struct Lanes {
    double damped[kLanes];  // 1 where the chain is damped: an undamped one's viscous work is 0, exactly
    // per step and lane: the viscous work of the two half steps, the kinetic energy the two
    // friction kicks took (sums over the bodies, in `batched_step._step`'s order), the unkicked
    // half-step velocity of body i and the viscous part of the force of contact i - 1
    double work1[kLanes], work2[kLanes], lost1[kLanes], lost2[kLanes], raw_prev[kLanes], d_prev[kLanes];
    // Per-lane values of the step kept for the tangent pass: what does not depend on the
    // direction is computed once per contact and step, not once per direction.
    double loss[kLanes];                                    // mu g dt/2
    double w_prev[kLanes], p_prev[kLanes], f_prev[kLanes];  // body i: kicked half-step and predicted velocity; force before
    double c1[kLanes];                                      // 1.5 eta
    // the two friction kicks' partial derivatives by the velocity kicked and by the loss
    double kick1_w[kLanes], kick1_loss[kLanes], kick2_w[kLanes], kick2_loss[kLanes];
    double body[kLanes];                         // the force on body i
    double force_slopes[kForceInputs * kLanes];  // contact i's, (kForceInputs, kLanes)
    // kPlastic and kTangent: the partial derivatives of contact i's largest overlap so far,
    // max(peak, overlap), by the peak before and by the step's overlap (1, 1/2 or 0)
    double peak_by_old[kLanes], peak_by_overlap[kLanes];
    double fresh[kLanes];  // kPlastic: 1 where contact i's largest overlap grew and its law yields
  };
  // the lanes of a step of dt (s) (inlined: `Lanes`' address stays in the loop)
  HC_LANES Lanes StepLanes(double dt) const;

  // where the trace of lane j's chain, channel c, set `set` (`record`) starts
  double* out(int64_t set, int64_t c, int64_t j) const {
    return set == 0 ? traces[c] + (lo + j) * n_samples : ttraces[c] + ((set - 1) * batch + lo + j) * n_samples;
  }

  // Loading (the constructor's parts, in its order)
  void LoadChains(const double* state0, const FullParams& p);
  void LoadSensors(const double* state0, const FullParams& p);
  void LoadBooks(const double* state0);
  void LoadTangents(const TangentInputs& tin);
  void LoadPlastic();
  void PrepareStep(double dt);
  // The packed state at the end, the block's own chains (kBooks)
  void StoreBooks() const;

  // The laws as the step applies them (`chain_step.h`)
  HC_LANES static double KickOf(double w, double loss_j) { return Kick(w, loss_j); }
  HC_LANES static double KickWithPartials(double w, double loss_j, double* by_w, double* by_loss);
  HC_LANES static double FrictionKick(double w, double loss_j, double* by_w, double* by_loss);
  template <class O, class R, class K, class Kv, class Dd, class S, class L0, class L1>
  HC_LANES static auto LawForce(const O& dl, const R& rate, const K& k, const Kv& kv, const Dd& d, const S& sp,
                                const L0& law0, const L1& law1, double* elastic);
  HC_LANES double LawIn(int64_t c, int64_t j, int which) const;
  template <bool kOwn>
  HC_LANES double ContactSlopes(double dl, double rate, double k, double c1j, double dash_j, double sp_j, int64_t c,
                                int64_t j, double* slopes, int64_t stride) const;
  template <bool kST>
  HC_LANES double ForceTangent(const double* slopes, int64_t stride, double tdl, double trate, double tk,
                               double t15e, double tdash_q, double tsp, double tlaw0, double tlaw1) const;
  HC_LANES void LawTangents(int64_t i, int64_t j, int64_t d, double* tlaw0, double* tlaw1) const;
  void Unload(int64_t i, int64_t j);
  double PlasticInput(int k, int64_t d, int64_t i, int64_t j) const;

  // The phases of a step (`chain_step.h`), in the order the loop runs them
  HC_LANES void SensorDrift(StepSize t, Lanes& __restrict l);
  HC_LANES void FirstBody(StepSize t, Lanes& __restrict l);
  HC_LANES void GrowPeaks(int64_t i, StepSize t, Lanes& __restrict l);
  template <bool kUK, bool kUM, bool kOwn>
  HC_LANES void Sweep(int64_t i, StepSize t, Lanes& __restrict l);
  template <bool kFixed>
  HC_LANES void TangentSweep(int64_t i, StepSize t, Lanes& __restrict l);
  HC_LANES void Wall(StepSize t, Lanes& __restrict l);
  HC_LANES void SensorKick(StepSize t, Lanes& __restrict l);
  // The recorded channels at a sample's end, from the new displacements and velocities
  HC_LANES void Record(Lanes& __restrict l);
};

template <class C>
FullBlock<C>::FullBlock(int64_t bodies_, int64_t lo_, int64_t batch_, int64_t n_samples_, int64_t steps_per_sample_,
                        double dt_, const double* state0, const FullParams& p, const std::vector<int64_t>& channels_,
                        const std::vector<double*>& traces_, int64_t directions, const TangentInputs& tin,
                        const std::vector<double*>& ttraces_, const BooksIO& books_)
    : bodies(bodies_), lo(lo_), batch(batch_), n_samples(n_samples_), steps_per_sample(steps_per_sample_),
      channels(channels_), traces(traces_), ttraces(ttraces_), books(books_), beads(p.beads),
      rows_x(bodies_ + 1), contacts(bodies_), law_rows(LawRows(kLaw, bodies_)),
      n_channels(static_cast<int64_t>(channels_.size())), D(kTangent ? directions : 0),
      valid(std::min(kLanes, batch_ - lo_)), ns(kSensors ? p.n_sensors : 0), sensor_rows(kSensors ? SensorRows(ns) : 0),
      first_row(4 * ns), peak_row(3 * rows_x), top_row(peak_row + (kPlastic ? contacts : 0)),
      vis_row(top_row + contacts), spent_row(vis_row + (kViscous ? rows_x : 0)),
      plastic_size(kPlastic ? contacts * kLanes : 0), record(n_channels, 1 + D, valid) {
  LoadChains(state0, p);
  LoadSensors(state0, p);
  LoadBooks(state0);
  LoadTangents(tin);
  LoadPlastic();
  PrepareStep(dt_);
}

template <class C>
void FullBlock<C>::LoadChains(const double* state0, const FullParams& p) {
  x.resize(rows_x * kLanes), v.resize(rows_x * kLanes), a.resize(rows_x * kLanes);
  inv.resize(rows_x * kLanes), kap.resize(contacts * kLanes), ov0.resize(contacts * kLanes);
  spr.resize(contacts * kLanes), ext.resize(rows_x * kLanes), eta.resize(kLanes), fr.resize(kLanes);
  dash.resize(kLanes);
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
  law.resize(kPower || kPlastic ? law_rows * kLanes : 0);
  if (kPower || kPlastic) Load<kLanes>(p.law, law_rows, lo, law.data(), valid);
  kvis.resize(contacts * kLanes), dsh.resize(contacts * kLanes);
  for (int64_t i = 0; i < contacts; ++i)
    for (int64_t j = 0; j < kLanes; ++j) {
      kvis[i * kLanes + j] = 1.5 * eta[j] * kap[i * kLanes + j];
      if (kDashpot) dsh[i * kLanes + j] = ContactDashpot(kap[i * kLanes + j], dash[j]);
    }
}

template <class C>
void FullBlock<C>::LoadSensors(const double* state0, const FullParams& p) {
  for (auto* rows : {&sf, &sr, &sd, &s_half, &s_pred, &s_amt, &s_quasi, &s_fb, &s_ff}) rows->resize(ns * kLanes);
  sp.resize(sensor_rows * kLanes);
  cut.resize(kSensors ? contacts * kLanes : 0), cut_rate.resize(kSensors ? contacts * kLanes : 0);
  back_of.assign(kSensors ? contacts : 0, -1), front_of.assign(kSensors ? contacts : 0, -1);
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
}

template <class C>
void FullBlock<C>::LoadBooks(const double* state0) {
  top.resize(kBooks ? contacts * kLanes : 0), vis.resize(kBooks && kViscous ? rows_x * kLanes : 0);
  mass.resize(kBooks && kFriction ? contacts * kLanes : 0), spent.resize(kBooks ? kLanes : 0);
  if constexpr (kBooks) {
    Load<kLanes>({state0 + top_row * batch, batch}, contacts, lo, top.data(), valid);
    if (kViscous) Load<kLanes>({state0 + vis_row * batch, batch}, rows_x, lo, vis.data(), valid);
    Load<kLanes>({state0 + spent_row * batch, batch}, 1, lo, spent.data(), valid);
    if (kFriction) Load<kLanes>(books.mass, contacts, lo, mass.data(), valid);
  }
  if constexpr (kPlastic && kBooks) {
    pk.resize(plastic_size);
    Load<kLanes>({state0 + peak_row * batch, batch}, contacts, lo, pk.data(), valid);
  }
}

template <class C>
void FullBlock<C>::LoadTangents(const TangentInputs& tin) {
  for (auto* rows : {&tx, &tv, &ta, &tinv, &text}) rows->resize(D * rows_x * kLanes);
  for (auto* rows : {&tkap, &tov0, &tspr}) rows->resize(D * contacts * kLanes);
  for (auto* rows : {&teta, &tfr, &tdash}) rows->resize(D * kLanes);
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
  const auto all_zero = [](const std::vector<double>& rows) {
    return std::all_of(rows.begin(), rows.end(), [](double t) { return t == 0.0; });
  };
  fixed_inputs = kTangent && all_zero(tinv) && all_zero(tkap) &&
                 (!kExtras || (all_zero(tov0) && all_zero(tspr) && all_zero(text)));
  for (auto* rows : {&tsf, &tsr, &tsd, &ts_half, &ts_pred, &ts_amt, &ts_fb, &ts_ff}) rows->resize(D * ns * kLanes);
  tsp.resize(D * sensor_rows * kLanes);
  tcut.resize(kSensors ? D * contacts * kLanes : 0), tcut_rate.resize(kSensors ? D * contacts * kLanes : 0);
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
  tlaw.resize(kPower || kPlastic ? D * law_rows * kLanes : 0);
  if (kTangent && (kPower || kPlastic)) LoadTangent<kLanes>(tin.law, D, law_rows, batch, lo, tlaw.data(), valid);
}

template <class C>
void FullBlock<C>::LoadPlastic() {
  for (auto* rows : {&pk, &res, &kpl, &yields}) rows->resize(plastic_size);
  dres.resize(kTangent ? kInputs * plastic_size : 0), dkpl.resize(kTangent ? kInputs * plastic_size : 0);
  tpk.resize(kTangent ? D * plastic_size : 0);
  if constexpr (kPlastic) {
    if constexpr (!kBooks) {
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
        Unload(i, j);
      }
  }
}

template <class C>
void FullBlock<C>::PrepareStep(double dt) {
  const double h = 0.5 * dt;
  uniform_k = UniformRows<kLanes>(kap.data(), contacts);
  const std::vector<char> uniform_kv = UniformRows<kLanes>(kvis.data(), contacts);
  const std::vector<char> uniform_d = UniformRows<kLanes>(dsh.data(), contacts);
  uniform_m = UniformRows<kLanes>(inv.data(), rows_x);
  for (int64_t i = 0; i < contacts; ++i) uniform_k[i] = uniform_k[i] && uniform_kv[i] && (!kDashpot || uniform_d[i]);
  for (auto* rows : {&tw_prev, &tp_prev, &tf_prev, &tloss, &t15eta}) rows->resize(D * kLanes);
  for (int64_t q = 0; q < D * kLanes; ++q) {
    tloss[q] = tfr[q] * h;
    t15eta[q] = 1.5 * teta[q];
  }
}

template <class C>
HC_LANES inline typename FullBlock<C>::Lanes FullBlock<C>::StepLanes(double dt) const {
  Lanes l;
  const double h = 0.5 * dt;
  for (int64_t j = 0; j < kLanes; ++j) {
    l.loss[j] = fr[j] * h;
    l.c1[j] = 1.5 * eta[j];
    if (kBooks) l.damped[j] = eta[j] != 0.0 || (kDashpot && dash[j] != 0.0) ? 1.0 : 0.0;
  }
  return l;
}

template <class C>
void FullBlock<C>::StoreBooks() const {
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

}  // namespace hertzchain
