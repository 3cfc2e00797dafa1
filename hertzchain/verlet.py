"""The phases of the velocity-Verlet step, written once for the JAX solvers: the reference
(`integrate.verlet_step`), the batched kernel (`batched_step`) and the driven chains' kernel
(`driven.kernel.step`). The native kernels' twin is `kernels/csrc/chain_verlet.h`; both keep
the same operations in the same order, so that every kernel agrees with the others to
round-off.

A step of length dt (s) with h = dt/2: a body's half kick v + h a (m/s, from the
acceleration a in m/s^2), its drift x + dt w (m, at the half-kicked velocity w), and after
the new forces the second half kick w + h a'. What a solver adds between them (friction
kicks, the driven chains' drag, the books) is its own.
"""

from __future__ import annotations


def half_kick(velocity_m_s, accel_m_s2, half_step_s):
    """A half kick: velocity + (dt/2) accel, m/s (also the velocity predicted at the step's
    end, from the half-kicked one and the old acceleration)."""
    return velocity_m_s + half_step_s * accel_m_s2


def drift(displacement_m, velocity_m_s, step_s):
    """A drift: displacement + dt velocity, m."""
    return displacement_m + step_s * velocity_m_s
