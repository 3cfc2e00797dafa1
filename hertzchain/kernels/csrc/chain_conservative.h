// The conservative velocity-Verlet step of `batched_step._step` (`chain_verlet.h`) on a host
// kernel's block of chains (`chain_kernel.cc`'s HertzChainForward): Hertz contacts, linear sensor springs, static
// overlaps and external forces of a preload, a wall or a free end, with or without the books
// (largest overlaps). Layouts: `chain_kernel.cc`.
#pragma once

#include <algorithm>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "chain_blocks.h"
#include "chain_lanes.h"
#include "chain_laws.h"
#include "chain_verlet.h"

namespace hertzchain {

// (static: every library its own copy, as a kernel's code differs with its library's defines)

// One contact of the conservative step (`ConservativeContact`) over a block's lanes, the
// force of contact i stored in `record` when given. kUniformK / kUniformM: kappa / the
// inverse mass of the row is one value for every lane.
template <int64_t kLanes, bool kPreload, bool kSprings, bool kBooks, bool kUniformK, bool kUniformM, bool kRecord>
static inline void ContactOverLanes(double dt, double h, double* __restrict xi, double* __restrict xn,
                                    const double* __restrict un, double* __restrict ui, const double* __restrict k,
                                    const double* __restrict o, const double* __restrict sp,
                                    const double* __restrict m, const double* __restrict e, double* __restrict top,
                                    double* __restrict force_before, double* __restrict record) {
  const double k0 = k[0], m0 = m[0];
  ForLanes<kLanes>([&](int64_t j) HC_LANES {
    const double force = ConservativeContact<kPreload, kSprings, kBooks>(
        dt, h, xi[j], xn[j], un[j], ui[j], kUniformK ? k0 : k[j], kPreload ? o[j] : 0.0, kSprings ? sp[j] : 0.0,
        kUniformM ? m0 : m[j], kPreload ? e[j] : 0.0, top[j], force_before[j]);
    if (kRecord) record[j] = force;
    force_before[j] = force;
  });
}

template <int64_t kLanes, bool kPreload, bool kSprings, bool kBooks>
static void RunBlock(int64_t bodies, int64_t lo, int64_t batch, int64_t n_samples,
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
  Load<kLanes>({state0, batch}, rows_x, lo, x.data());
  Load<kLanes>({state0 + rows_x * batch, batch}, rows_x, lo, u.data());
  if (kBooks) Load<kLanes>({state0 + 2 * rows_x * batch, batch}, contacts, lo, mx.data());
  Load<kLanes>(inv_mass, rows_x, lo, inv.data());
  Load<kLanes>(kappa, contacts, lo, kap.data());
  Load<kLanes>(overlap0, contacts, lo, ov0.data());
  Load<kLanes>(spring, contacts, lo, spr.data());
  Load<kLanes>(external, rows_x, lo, ext.data());
  const std::vector<char> uniform_k = UniformRows<kLanes>(kap.data(), contacts);
  const std::vector<char> uniform_m = UniformRows<kLanes>(inv.data(), rows_x);
  // the channel recording each contact (-1: none); a contact recorded twice is copied
  std::vector<int64_t> channel_of(contacts, -1);
  for (int64_t c = n_channels - 1; c >= 0; --c) channel_of[channels[c]] = c;

  double force_before[kLanes];
  SampleBuffer<kLanes> record(n_channels, 1, kLanes);
  auto out = [&](int64_t, int64_t c, int64_t j) { return traces[c] + (lo + j) * n_samples; };

  for (int64_t n = 0; n < n_samples; ++n) {
    for (int64_t s = 0; s < steps_per_sample; ++s) {
      // Drift of the striker, then, body by body, the drift of the next body, the force
      // of the contact between them and the full kick of this body (v = u + h a, then
      // u = v + h a, as the JAX kernel rounds them). The forces of the sample's last step
      // are the recorded ones (of the new displacements, as the JAX kernel records them).
      const bool last = s == steps_per_sample - 1;
      for (int64_t j = 0; j < kLanes; ++j) {
        x[j] = x[j] + dt * u[j];
        force_before[j] = 0.0;
      }
      for (int64_t i = 0; i < contacts; ++i) {
        double* dst = last && channel_of[i] >= 0 ? record.slot(0, channel_of[i]) : nullptr;
        auto sweep = [&](auto uk, auto um, auto rec) {
          ContactOverLanes<kLanes, kPreload, kSprings, kBooks, decltype(uk)::value, decltype(um)::value,
                           decltype(rec)::value>(
              dt, h, &x[i * kLanes], &x[(i + 1) * kLanes], &u[(i + 1) * kLanes], &u[i * kLanes], &kap[i * kLanes],
              &ov0[i * kLanes], &spr[i * kLanes], &inv[i * kLanes], &ext[i * kLanes], &mx[i * kLanes],
              force_before, dst);
        };
        using T = std::true_type;
        using F = std::false_type;
        const int which = (uniform_k[i] ? 4 : 0) + (uniform_m[i] ? 2 : 0) + (dst ? 1 : 0);
        switch (which) {
          case 0: sweep(F{}, F{}, F{}); break;
          case 1: sweep(F{}, F{}, T{}); break;
          case 2: sweep(F{}, T{}, F{}); break;
          case 3: sweep(F{}, T{}, T{}); break;
          case 4: sweep(T{}, F{}, F{}); break;
          case 5: sweep(T{}, F{}, T{}); break;
          case 6: sweep(T{}, T{}, F{}); break;
          default: sweep(T{}, T{}, T{}); break;
        }
      }
      // The wall's row (inverse mass 0: it stays at rest, as in the JAX kernel).
      double* uw = &u[contacts * kLanes];
      const double* mw = &inv[contacts * kLanes];
      const double* ew = &ext[contacts * kLanes];
      for (int64_t j = 0; j < kLanes; ++j) {
        double u = uw[j];
        ConservativeWall<kPreload>(h, u, mw[j], kPreload ? ew[j] : 0.0, force_before[j]);
        uw[j] = u;
      }
    }
    // a contact recorded by two channels: the second a copy of the first
    for (int64_t c = 0; c < n_channels; ++c)
      if (channel_of[channels[c]] != c) std::copy_n(record.slot(0, channel_of[channels[c]]), kLanes, record.slot(0, c));
    record.advance(out);
  }
  if (record.buffered) record.flush(out);

  auto store = [&](const std::vector<double>& block, int64_t rows, double* dst) {
    for (int64_t r = 0; r < rows; ++r)
      for (int64_t j = 0; j < kLanes; ++j) dst[r * batch + lo + j] = block[r * kLanes + j];
  };
  store(x, rows_x, state);
  store(u, rows_x, state + rows_x * batch);
  if (kBooks) store(mx, contacts, state + 2 * rows_x * batch);
}

}  // namespace hertzchain
