// Fixed runs of the driven lock-in kernel (`hertzchain/kernels/csrc/driven_kernel.cc`) and of
// the one-thread-per-chain kernel's host emulation (`chain_kernel_thread.cu`), for instruction
// counts under callgrind (`benchmarks/driven_thread_step.py`). Built with -DHC_DRIVEN_RUN
// (the driven kernel) or -DHC_THREAD_RUN (the thread kernel, with HC_HOST_EMULATION and
// HC_ROWS=12); each calls the kernel's block or thread functions directly:
//   driven_thread_step_driver forward|tangent
// driven: one block of 16 runs of a two-bead damped chain (1000 steps: a 480-step ramp, a
// 192-step lock-in window, two harmonics), the tangent along four directions (kappa, eta,
// the drive's amplitude, the step); thread: 8 chains of 10 beads, a striker and a wall,
// damped and with friction, 4000 steps and two recorded contacts, the tangent along three
// directions (eta, friction, the striker's speed).
#include <cmath>
#include <vector>

#include "step_driver_main.h"

#if defined(HC_DRIVEN_RUN)
#include "driven_kernel.cc"
#elif defined(HC_THREAD_RUN)
#include "chain_kernel_thread.cu"
#else
#error "build with -DHC_DRIVEN_RUN or -DHC_THREAD_RUN"
#endif

namespace {

double checksum = 0.0;

void Report(const std::vector<double>& values) {
  for (double f : values) checksum += f;
}

#if defined(HC_DRIVEN_RUN)
constexpr int64_t kBeads = 2, kPeriod = 48, kRamp = 480, kSteps = 1000, kWindow = 192, kHarmonics = 2;
constexpr int64_t kDirections = 4;

template <bool kTangent>
void Once() {
  const int64_t B = kLanes;
  std::vector<double> inv_mass(kBeads * B), gamma(kBeads, 300.0), kappa(kBeads + 1), overlap0(kBeads + 1);
  std::vector<double> eta = {2e-7}, amplitude(B), dt(B), omega(B);
  for (int64_t i = 0; i < kBeads; ++i)
    for (int64_t b = 0; b < B; ++b) inv_mass[i * B + b] = 1.0 / (0.02 + 0.005 * static_cast<double>(i));
  for (int64_t c = 0; c <= kBeads; ++c) {
    kappa[c] = 1.0e10 + 1.0e9 * static_cast<double>(c);
    overlap0[c] = 5e-9;
  }
  for (int64_t b = 0; b < B; ++b) {
    const double f = 1500.0 + 300.0 * static_cast<double>(b);  // Hz
    amplitude[b] = b % 2 == 0 ? 1e-9 : 3e-8;
    dt[b] = 1.0 / (f * kPeriod);
    omega[b] = 2.0 * 3.141592653589793 * f;
  }
  std::vector<double> cs(kPeriod), sn(kPeriod), shape(kRamp + 1), slope(kRamp + 1);
  for (int64_t k = 0; k < kPeriod; ++k) {
    cs[k] = std::cos(2.0 * 3.141592653589793 * static_cast<double>(k) / kPeriod);
    sn[k] = std::sin(2.0 * 3.141592653589793 * static_cast<double>(k) / kPeriod);
  }
  for (int64_t j = 0; j <= kRamp; ++j) {
    const double s = static_cast<double>(j) / kRamp;
    shape[j] = s * s * (3.0 - 2.0 * s);
    slope[j] = 6.0 * s * (1.0 - s);
  }
  std::vector<double> reference(2 * kHarmonics * kWindow);
  for (int64_t h = 0; h < kHarmonics; ++h)
    for (int64_t w = 0; w < kWindow; ++w) {
      const double phase = 2.0 * 3.141592653589793 * (h == 0 ? 1.0 : 0.5) * static_cast<double>(w) / kPeriod;
      reference[h * kWindow + w] = std::cos(phase) / kWindow;
      reference[(kHarmonics + h) * kWindow + w] = -std::sin(phase) / kWindow;
    }
  Run r{kBeads, kSteps, kRamp, kPeriod, kWindow, kHarmonics, 1, B, false,
        cs.data(), sn.data(), shape.data(), slope.data(), reference.data()};
  const Inputs in{{inv_mass.data(), B}, {gamma.data(), 1}, {kappa.data(), 1}, {overlap0.data(), 1},
                  {eta.data(), 1},      {amplitude.data(), B}, {dt.data(), B}, {omega.data(), B}};
  // directions: kappa (every contact), eta, the amplitude, the step
  std::vector<double> t_kappa(kDirections * (kBeads + 1) * B, 0.0), t_eta(kDirections * B, 0.0);
  std::vector<double> t_amplitude(kDirections * B, 0.0), t_dt(kDirections * B, 0.0), zero(4 * B, 0.0);
  for (int64_t b = 0; b < B; ++b) {
    for (int64_t c = 0; c <= kBeads; ++c) t_kappa[(0 * (kBeads + 1) + c) * B + b] = kappa[c];
    t_eta[1 * B + b] = eta[0];
    t_amplitude[2 * B + b] = amplitude[b];
    t_dt[3 * B + b] = dt[b];
  }
  const Tangent none{zero.data(), true};
  const TangentInputs tin{none, none, {t_kappa.data(), false}, none, {t_eta.data(), false},
                          {t_amplitude.data(), false}, {t_dt.data(), false}, none};
  std::vector<double> sums(2 * kHarmonics * B), tsums(kDirections * 2 * kHarmonics * B);
  RunDrivenBlock<true, kTangent>(r, 0, in, tin, kTangent ? kDirections : 0, sums.data(), tsums.data());
  Report(sums);
  if (kTangent) Report(tsums);
}
#else
constexpr int64_t kBatch = 8, kSamples = 100, kStepsPerSample = 40, kDirections = 3;
constexpr double kMass = 2.09e-3, kKappa = 6.55e9, kEta = 2e-6, kMuG = 0.19 * 9.81;

template <bool kTangent>
void Once() {
  std::vector<double> state0(3 * kRows * kBatch, 0.0), inv(kRows, 1.0 / kMass), kappa(kContacts, kKappa);
  std::vector<double> zeros(4 * kRows, 0.0), eta = {kEta}, friction = {kMuG};
  inv[kContacts] = 0.0;  // the wall
  for (int64_t b = 0; b < kBatch; ++b) state0[kRows * kBatch + b] = 0.2 + 0.1 * static_cast<double>(b);
  std::vector<double> t_state0(kDirections * 3 * kRows * kBatch, 0.0), t_eta(kDirections * kBatch, 0.0);
  std::vector<double> t_friction(kDirections * kBatch, 0.0), t_zero(4 * kRows * kBatch, 0.0);
  for (int64_t b = 0; b < kBatch; ++b) {
    t_eta[0 * kBatch + b] = 1.0;
    t_friction[1 * kBatch + b] = 1.0;
    t_state0[(2 * 3 * kRows + kRows) * kBatch + b] = state0[kRows * kBatch + b];
  }
  FullArgs A{};
  A.batch = kBatch;
  A.n_samples = kSamples;
  A.steps_per_sample = kStepsPerSample;
  A.directions = kTangent ? kDirections : 1;
  A.dt = 2e-8;
  A.state0 = state0.data();
  const Param zero{zeros.data(), 1};
  A.inv_mass = {inv.data(), 1};
  A.kappa = {kappa.data(), 1};
  A.overlap0 = A.spring = A.external = A.dashpot = zero;
  A.eta = {eta.data(), 1};
  A.friction = {friction.data(), 1};
  const Tangent none{t_zero.data(), true};
  A.t_state0 = {t_state0.data(), false};
  A.t_inv_mass = A.t_kappa = A.t_overlap0 = A.t_spring = A.t_external = A.t_dashpot = none;
  A.t_eta = {t_eta.data(), false};
  A.t_friction = {t_friction.data(), false};
  A.channels = Channels{};
  A.channels.count = 2;
  A.channels.contact[0] = 2;
  A.channels.contact[1] = 6;
  A.channels.mask[0] = (uint64_t{1} << 2) | (uint64_t{1} << 6);
  std::vector<double> traces(2 * kSamples * kBatch), ttraces(2 * kDirections * kSamples * kBatch);
  for (int c = 0; c < 2; ++c) {
    A.out.trace[c] = &traces[c * kSamples * kBatch];
    A.out.tangent[c] = &ttraces[c * kDirections * kSamples * kBatch];
  }
  const int64_t threads = kBatch * (kTangent ? kDirections : 1);
  Launch(0, threads, FullThread<true, true, kTangent, true, false>{A});
  Report(traces);
  if (kTangent) Report(ttraces);
}
#endif

}  // namespace

int main(int argc, char** argv) {
  return RunNamed(argc, argv, {{"forward", Once<false>}, {"tangent", Once<true>}}, checksum);
}
