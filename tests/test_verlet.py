"""The velocity-Verlet step (`verlet.step`) against closed forms: free fall, the damped
harmonic oscillator, the terminal velocity under drag, time reversal, the kick limit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain  # noqa: F401  (float64)
from hertzchain import verlet


def _run(x, v, dt, steps, accel, **options):
    """`steps` steps of `verlet.step` under accel(x, v) (no forces kept)."""
    a = accel(x, v)

    def body(carry, _):
        s = verlet.step(*carry, dt, lambda y, w: (accel(y, w), None), **options)
        return (s.displacement_m, s.velocity_m_s, s.accel_m_s2), None

    return jax.lax.scan(body, (jnp.asarray(x), jnp.asarray(v), a), None, length=steps)[0]


def test_constant_acceleration_is_integrated_exactly():
    # velocity Verlet is exact for quadratic motion: x = x0 + v0 t + g t^2 / 2, v = v0 + g t
    g, x0, v0, dt, n = -9.81, 1.0, 2.5, 1e-3, 1000
    x, v, _ = _run(x0, v0, dt, n, lambda x, v: jnp.full_like(x, g))
    t = n * dt
    assert float(x) == pytest.approx(x0 + v0 * t + 0.5 * g * t * t, rel=1e-12)
    assert float(v) == pytest.approx(v0 + g * t, rel=1e-12)


def _damped_oscillator(t, omega, gamma, x0):
    """x(t) of x'' = -omega^2 x - gamma x', x(0) = x0, x'(0) = 0 (underdamped)."""
    wd = np.sqrt(omega**2 - gamma**2 / 4)
    return x0 * np.exp(-gamma * t / 2) * (np.cos(wd * t) + gamma / (2 * wd) * np.sin(wd * t))


@pytest.mark.parametrize("gamma", [0.0, 0.3])
def test_damped_oscillator_converges_at_second_order(gamma):
    # the drag enters as verlet.step's drag_rate_per_s (trapezoidal), the spring as the force
    # (t_end off the oscillation's extremum, where a phase error shows at first order)
    omega, t_end = 2.0 * np.pi, 3.2
    errors = []
    for n in (640, 1280, 2560):
        x, _, _ = _run(1.0, 0.0, t_end / n, n, lambda x, v: -(omega**2) * x,
                       drag_rate_per_s=None if gamma == 0.0 else gamma)
        errors.append(abs(float(x) - _damped_oscillator(t_end, omega, gamma, 1.0)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all(np.abs(ratios - 4.0) < 0.15), ratios


def test_drag_gives_the_terminal_velocity_at_any_step():
    # under a constant force and drag gamma the scheme's fixed point is v = a / gamma exactly,
    # and a step far beyond 2 / gamma stays stable (the drag is implicit)
    a, gamma = 3.0, 50.0
    for dt in (1e-3, 1.0):
        _, v, _ = _run(0.0, 0.0, dt, 4000, lambda x, v: jnp.full_like(x, a), drag_rate_per_s=gamma)
        assert float(v) == pytest.approx(a / gamma, rel=1e-9)


def test_undamped_step_is_time_reversible():
    # a nonlinear (Hertz-like) force: run forward, flip the velocity, run back: the start again
    def accel(x, v):
        return -jnp.maximum(x, 0.0) ** 1.5 * 1e3 - 0.1 * x

    x, v, _ = _run(jnp.array([0.2, -0.1]), jnp.array([0.0, 0.4]), 1e-3, 2000, accel)
    back, v_back, _ = _run(x, -v, 1e-3, 2000, accel)
    np.testing.assert_allclose(np.asarray(back), [0.2, -0.1], atol=1e-11)
    np.testing.assert_allclose(np.asarray(v_back), [0.0, -0.4], atol=1e-11)


def test_the_kick_limit_acts_before_the_drift():
    # a limit that stops the bodies: they do not move, the limit's extra comes back, and the
    # books' first-half velocity is the one before the limit
    stepped = verlet.step(jnp.array([1.0]), jnp.array([2.0]), jnp.array([4.0]), 0.5,
                          lambda x, v: (jnp.zeros_like(x), v),
                          limit=lambda w: (jnp.zeros_like(w), "stopped"))
    assert float(stepped.displacement_m[0]) == 1.0
    assert float(stepped.half_kicked_m_s[0]) == 2.0 + 0.25 * 4.0
    assert float(stepped.half_velocity_m_s[0]) == 0.0
    # the forces are evaluated at the predicted velocity w + h a (w after the limit)
    assert float(stepped.forces[0]) == 0.25 * 4.0
    assert stepped.limited == "stopped"
