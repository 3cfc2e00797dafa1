// The velocity-Verlet step of `verlet.step` (as `batched_step._step` runs it) on one chain's
// bodies and contacts, written once for every native kernel that runs it: a lane of the host's blocks of chains
// (`chain_conservative.h`, `chain_step.h`), a thread of the one-thread-per-chain kernels
// (`chain_kernel_thread.cu`, on the host or a GPU) and a lane of the driven chains' blocks
// (`driven_kernel.cc`: its drag in the acceleration of the first half kick and implicit in
// the second, as that kick's function). The arithmetic is the JAX kernel's,
// operation for operation and in its order (no contraction into fused multiply-adds), so
// that every kernel agrees with it to round-off.
//
// The conservative step keeps u = v + (dt/2) a: the striker's drift, then contact by contact
// the drift of the next body, the contact's force and the full kick of the body behind it,
// then the wall's kick. The full step (damping, friction) keeps v and a apart: a body's first
// half kick, friction kick and drift (`HalfKickAndDrift`), the contact's force at the
// predicted velocities (`chain_laws.h`), the second half kick and friction kick of the body
// behind it (`SecondHalfKick`). Its phases are templates over the number type and the
// friction kick: run on doubles with `Kick` for the values, on dual numbers for the thread
// kernel's tangents, and on tangents with the friction kick's linearisation for the host's
// tangent passes (the phases are linear in the state but for that kick).
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

// A body's first half kick and drift in the full step: w = kick(v + h a) (`kick`: the friction
// kick, or the identity), x = x + dt w; returns w, and `predicted` = w + h a, the velocity the
// contacts' rates are taken at. T: a double (m, m/s, m/s^2), a dual number, or a tangent; H,
// the step's: a double, or a dual number where the step has a tangent (the driven kernel's).
template <class T, class H, class KickFn>
HC_HD HC_INLINE T HalfKickAndDrift(const T& v, const T& a, const H& h, const H& dt, const KickFn& kick, T& x,
                                   T& predicted) {
  const T w = kick(v + h * a);
  x = x + dt * w;
  predicted = w + h * a;
  return w;
}

// A body's second half kick in the full step: kick(w + h a), w its half-kicked velocity and a
// its new acceleration.
template <class T, class H, class KickFn>
HC_HD HC_INLINE T SecondHalfKick(const T& w, const T& a, const H& h, const KickFn& kick) {
  return kick(w + h * a);
}

}  // namespace hertzchain
