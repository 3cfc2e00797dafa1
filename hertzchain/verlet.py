"""The velocity-Verlet step, written once for the JAX solvers: the reference
(`integrate.verlet_step`), the batched kernel's full step (`batched_step`) and the driven
chains' kernel (`driven.kernel.step`) are this `step` with their own forces, drag and
friction. The batched kernel's conservative step (one velocity row less, `batched_step`) is
the same scheme regrouped. The native kernels' twin is `kernels/csrc/chain_verlet.h`; both
keep the same operations in the same order, so that every kernel agrees with the others to
round-off.

A step of length dt (s) with h = dt/2, from displacements x (m), velocities v (m/s) and
accelerations a (m/s^2), with a drag rate $\\gamma$ (1/s; none by default):

    w  = v + h (a - gamma v)          the half kick
    w  = limit(w)                     the solver's kick limit (track friction), if any
    x' = x + dt w                     the drift
    a' = accel_at(x', w + h (a - gamma v))
                                      the forces at the new positions and the velocity
                                      predicted at the step's end
    v' = (w + h a') / (1 + h gamma)   the second half kick

The drag $-\\gamma v$ is treated by the trapezoidal rule (implicit in the second half kick,
solved in closed form): the scheme stays symmetric, second order and stable for any drag.
What a solver adds around the step (the books, the compliant sensors, a friction kick at
the step's end) is its own.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple


def half_kick(velocity_m_s, accel_m_s2, half_step_s):
    """A half kick: velocity + (dt/2) accel, m/s (also the velocity predicted at the step's
    end, from the half-kicked one and the old acceleration)."""
    return velocity_m_s + half_step_s * accel_m_s2


def drift(displacement_m, velocity_m_s, step_s):
    """A drift: displacement + dt velocity, m."""
    return displacement_m + step_s * velocity_m_s


class Stepped(NamedTuple):
    """What one `step` gives.

    **Fields:**

    - `displacement_m`: x', m.
    - `half_kicked_m_s`: the half-kicked velocity before the kick limit, m/s (the books'
      work over the first half step reads it).
    - `half_velocity_m_s`: the velocity the bodies drifted at (after the limit), m/s.
    - `velocity_m_s`: v' at the step's end, m/s.
    - `accel_m_s2`: a' at the step's end, m/s^2.
    - `forces`: what `accel_at` gave beside the acceleration (the solver's own).
    - `limited`: what `limit` gave beside the velocity (None without a limit).
    """

    displacement_m: Any
    half_kicked_m_s: Any
    half_velocity_m_s: Any
    velocity_m_s: Any
    accel_m_s2: Any
    forces: Any
    limited: Any


def step(
    displacement_m,
    velocity_m_s,
    accel_m_s2,
    step_s,
    accel_at: Callable[[Any, Any], tuple[Any, Any]],
    *,
    drag_rate_per_s=None,
    limit: Callable[[Any], tuple[Any, Any]] | None = None,
) -> Stepped:
    """One velocity-Verlet step of length `step_s` (s; a scalar, or an array that
    broadcasts over the runs) from displacements, velocities and accelerations (m, m/s,
    m/s^2; see the module docstring).

    **Arguments:**

    - `accel_at(x_m, v_m_s) -> (accel_m_s2, forces)`: the acceleration at displacements x
      and velocities v (the predicted ones at the step's end), and whatever else the
      solver keeps of its force evaluation (returned as `Stepped.forces`).
    - `drag_rate_per_s`: viscous drag $\\gamma$ of every body, 1/s (None: none).
    - `limit(w_m_s) -> (w_m_s, limited)`: a kick limit applied to the half-kicked velocity
      before the drift (track friction; None: none).

    **Returns:** `Stepped`.
    """
    h = 0.5 * step_s
    kick_accel = accel_m_s2
    if drag_rate_per_s is not None:
        kick_accel = accel_m_s2 - drag_rate_per_s * velocity_m_s
    kicked = half_kick(velocity_m_s, kick_accel, h)
    moving, limited = (kicked, None) if limit is None else limit(kicked)
    displacement = drift(displacement_m, moving, step_s)
    accel, forces = accel_at(displacement, half_kick(moving, kick_accel, h))
    velocity = half_kick(moving, accel, h)
    if drag_rate_per_s is not None:
        velocity = velocity / (1.0 + h * drag_rate_per_s)
    return Stepped(displacement, kicked, moving, velocity, accel, forces, limited)
