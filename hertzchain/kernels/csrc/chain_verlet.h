// The conservative velocity-Verlet step of `batched._step` on one chain's bodies and
// contacts, written once for every native kernel that runs it: a lane of the host's blocks of
// chains (`chain_conservative.h`) and a thread of the one-thread-per-chain kernels
// (`chain_kernel_thread.cu`, on the host or a GPU). The step keeps u = v + (dt/2) a: the
// striker's drift, then contact by contact the drift of the next body, the contact's force
// and the full kick of the body behind it, then the wall's kick. The arithmetic is the JAX
// kernel's, operation for operation and in its order (no contraction into fused
// multiply-adds), so that every kernel agrees with it to round-off.
#pragma once

#include "chain_laws.h"

namespace hertzchain {

// The full kick of a body: its u (m/s) by its acceleration a (m/s^2) over the step's halves
// h = dt/2 (s), v = u + h a, then u = v + h a, as the JAX kernel rounds them.
HC_HD HC_INLINE void FullKick(double& u, double h, double a) {
  const double v = u + h * a;
  u = v + h * a;
}

// Contact i of the conservative step: body i + 1 drifts (its displacement `next` (m) by its
// u `next_u` (m/s) over dt (s)), contact i's force (N) follows from the overlap x_i - x_{i+1}
// (+ the static overlap `overlap0` (m) with kPreload) by Hertz's law with stiffness `kappa`
// (N/m^1.5) and, with kSprings, the sensor spring `spring` (N/m); with kBooks `top` keeps the
// largest overlap so far (m); then body i, behind the contact, gets its full kick
// (`FullKick`) from `force_before` - force (+ the external force `external` (N) with kPreload)
// times its inverse mass `inv_mass` (1/kg). Returns the contact's force, the next contact's
// `force_before`.
template <bool kPreload, bool kSprings, bool kBooks>
HC_HD HC_INLINE double ConservativeContact(double dt, double h, double x, double& next, double next_u, double& u,
                                           double kappa, double overlap0, double spring, double inv_mass,
                                           double external, double& top, double force_before) {
  next = next + dt * next_u;
  const double overlap = kPreload ? (x - next) + overlap0 : x - next;
  const double force = ElasticForce<kSprings>(overlap, kappa, spring);
  if (kBooks) top = overlap > top ? overlap : top;
  double body = force_before - force;
  if (kPreload) body = body + external;
  FullKick(u, h, body * inv_mass);
  return force;
}

// The wall's row after the last contact: its full kick from the last contact's force
// `force_before` (+ the external force `external` with kPreload) times its inverse mass (0 for
// a wall at rest, as in the JAX kernel).
template <bool kPreload>
HC_HD HC_INLINE void ConservativeWall(double h, double& u, double inv_mass, double external, double force_before) {
  double body = force_before;
  if (kPreload) body = body + external;
  FullKick(u, h, body * inv_mass);
}

}  // namespace hertzchain
