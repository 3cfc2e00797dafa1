// A fixed run of the host kernels' blocks (`hertzchain/kernels/csrc/chain_kernel.cc`), for instruction
// counts under callgrind (`benchmarks/native_step.py`): built with HC_PART=0, so that none
// of the library's FFI handlers is compiled, only the block functions this file calls.
//   native_step_driver conservative|forward|tangent
// conservative: the conservative step (RunBlock), forward: the full step damped and with
// friction (RunFullBlock, the forces only), tangent: the same run with its tangents along
// three directions (damping, friction, impact speed: a fit iteration's value and jacfwd),
// each one block of 8 chains of 20 bodies and a wall, 4000 steps, two recorded contacts.
#include <vector>

#include "chain_kernel.cc"
#include "step_driver_main.h"

namespace {

constexpr int64_t kBodies = 20, kRows = kBodies + 1, kBatch = 8, kSamples = 100, kStepsPerSample = 40;
constexpr int64_t kDirections = 3;
constexpr double kDt = 2e-8;                   // s
constexpr double kMass = 2.09e-3;              // kg, a 4 mm steel bead
constexpr double kKappa = 6.55e9;              // N/m^1.5
constexpr double kEta = 2e-6, kMuG = 0.19 * 9.81;  // s, m/s^2

double checksum = 0.0;

void Report(const std::vector<std::vector<double>>& traces) {
  for (const auto& t : traces)
    for (double f : t) checksum += f;
}

std::vector<double> InverseMasses() {
  std::vector<double> inv(kRows, 1.0 / kMass);
  inv[kBodies] = 0.0;  // the wall
  return inv;
}

// striker speeds 0.2 .. 0.9 m/s, one per chain
double Speed(int64_t b) { return 0.2 + 0.1 * static_cast<double>(b); }

void Conservative() {
  std::vector<double> state0(2 * kRows * kBatch, 0.0), state(2 * kRows * kBatch);
  for (int64_t b = 0; b < kBatch; ++b) state0[kRows * kBatch + b] = Speed(b);
  const std::vector<double> inv = InverseMasses(), kappa(kBodies, kKappa), zeros(kRows, 0.0);
  const std::vector<int64_t> channels = {2, 6};
  std::vector<std::vector<double>> traces(2, std::vector<double>(kBatch * kSamples));
  std::vector<double*> outs = {traces[0].data(), traces[1].data()};
  RunBlock<8, false, false, false>(kBodies, 0, kBatch, kSamples, kStepsPerSample, kDt, state0.data(),
                                   {inv.data(), 1}, {kappa.data(), 1}, {zeros.data(), 1}, {zeros.data(), 1},
                                   {zeros.data(), 1}, channels, state.data(), outs);
  Report(traces);
}

template <bool kTangent>
void Full() {
  std::vector<double> state0(3 * kRows * kBatch, 0.0);
  for (int64_t b = 0; b < kBatch; ++b) state0[kRows * kBatch + b] = Speed(b);
  const std::vector<double> inv = InverseMasses(), kappa(kBodies, kKappa), zeros(4 * kRows, 0.0);
  const std::vector<double> eta = {kEta}, friction = {kMuG}, law(2, 0.0);
  FullParams p{{inv.data(), 1},  {kappa.data(), 1},    {zeros.data(), 1}, {zeros.data(), 1}, {zeros.data(), 1},
               {eta.data(), 1}, {friction.data(), 1}, {zeros.data(), 1}, {law.data(), 1},   {zeros.data(), 1}};
  const std::vector<int64_t> channels = {2, 6};
  std::vector<std::vector<double>> traces(2, std::vector<double>(kBatch * kSamples));
  std::vector<std::vector<double>> ttraces(2, std::vector<double>(kDirections * kBatch * kSamples));
  std::vector<double*> outs = {traces[0].data(), traces[1].data()};
  std::vector<double*> touts = {ttraces[0].data(), ttraces[1].data()};
  // directions: eta, mu g, the striker's speed (state0's v of body 0)
  std::vector<double> t_state0(kDirections * 3 * kRows * kBatch, 0.0), t_eta(kDirections * kBatch, 0.0);
  std::vector<double> t_friction(kDirections * kBatch, 0.0), t_zero(4 * kRows * kBatch, 0.0);
  for (int64_t b = 0; b < kBatch; ++b) {
    t_eta[0 * kBatch + b] = 1.0;
    t_friction[1 * kBatch + b] = 1.0;
    t_state0[(2 * 3 * kRows + kRows) * kBatch + b] = Speed(b);
  }
  const Tangent zero{t_zero.data(), true};
  TangentInputs tin{{t_state0.data(), false}, zero, zero, zero, zero, zero, {t_eta.data(), false},
                    {t_friction.data(), false}, zero, zero, zero};
  RunFullBlock<8, true, true, kTangent, true, false, false, Law::kHertz, false>(
      kBodies, 0, kBatch, kSamples, kStepsPerSample, kDt, state0.data(), p, channels, outs,
      kTangent ? kDirections : 0, tin, touts, BooksIO{});
  Report(traces);
  if (kTangent) Report(ttraces);
}

}  // namespace

int main(int argc, char** argv) {
  return RunNamed(argc, argv, {{"conservative", Conservative}, {"forward", Full<false>}, {"tangent", Full<true>}},
                  checksum);
}
