"""Reference solver on diffrax: the same chain, an adaptive high-order integrator.

Used to cross-check the velocity-Verlet solver (`hertzchain.simulate`). Same inputs and
outputs: it takes a `ChainSetup` and returns `Traces`. The state carries displacements,
velocities and the running energy dissipated and impulses, so the ledger is integrated to
the solver's tolerance. Coulomb track friction has no smooth ODE form; here it is
$-\\mu m g \\tanh(v / v_{reg})$ with `friction_smoothing_m_s` (default 1e-6 m/s), which
is close to, but not exactly, the Verlet solver's exact stick-slip.
"""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp

from .chain import ChainSetup, build_model
from .forces import chain_forces, initial_velocity
from .integrate import Recording, _assemble, _layout, _sample, check_yield
from .timegrid import TimeGrid


class _Solution(eqx.Module):
    displacement_m: jax.Array
    velocity_m_s: jax.Array
    dissipated_viscous_j: jax.Array
    dissipated_friction_j: jax.Array
    wall_impulse_n_s: jax.Array
    friction_impulse_n_s: jax.Array


def _scales(model):
    """Typical sizes of each state component, used to make the solver's state O(1)."""
    speed = model.striker_velocity_m_s
    mass = model.mass_kg[0]
    energy = 0.5 * mass * speed**2
    overlap = (1.25 * mass * speed**2 / model.kappa[0]) ** 0.4
    return _Solution(overlap, speed, energy, energy, mass * speed, mass * speed)


def _vector_field(model, friction_smoothing_m_s):
    scale = _scales(model)

    def field(t, y: _Solution, args):
        u = y.displacement_m * scale.displacement_m
        v = y.velocity_m_s * scale.velocity_m_s
        forces = chain_forces(model, u, v)
        friction = -model.mass_kg * model.friction_decel_m_s2 * jnp.tanh(v / friction_smoothing_m_s)
        rates = _Solution(
            displacement_m=v,
            velocity_m_s=(forces.body_force_n + friction) / model.mass_kg,
            dissipated_viscous_j=-jnp.sum(forces.body_viscous_force_n * v),
            dissipated_friction_j=-jnp.sum(friction * v),
            wall_impulse_n_s=forces.wall_total_n,
            friction_impulse_n_s=jnp.sum(friction),
        )
        return jax.tree_util.tree_map(lambda rate, size: rate / size, rates, scale)

    return field


def simulate_reference(
    setup: ChainSetup,
    *,
    t_end_s: float = 2.5e-3,
    sample_interval_s: float = 1e-6,
    contacts=(),
    rtol: float = 1e-10,
    atol: float = 1e-12,
    friction_smoothing_m_s: float = 1e-6,
    record_all: bool = False,
    max_steps: int = 2_000_000,
    on_yield: str = "warn",
):
    """Simulate `setup` with diffrax (Dopri8, PID step control); same outputs as `simulate`.

    **Arguments:** as `simulate` (`on_yield`: `"warn"`, `"raise"` or `"ignore"` when a force
    exceeds the yield force), plus `rtol` and `atol` (tolerances on the state made
    dimensionless by the striker's speed, its kinetic energy and momentum and its first
    collision's overlap), and `friction_smoothing_m_s` (see module docstring).
    """
    if on_yield not in ("warn", "raise", "ignore"):
        raise ValueError(f"on_yield must be 'warn', 'raise' or 'ignore', got {on_yield!r}.")
    if setup.plasticity:
        raise ValueError(
            "The reference solver integrates an ODE and cannot follow the history of plastic "
            "contacts; use hertzchain.simulate for elastic-plastic contact laws."
        )
    recording = Recording(tuple(int(k) for k in contacts), bool(record_all))
    _layout(setup, recording)
    n_samples = round(t_end_s / sample_interval_s)
    grid = TimeGrid(dt_s=sample_interval_s, steps_per_sample=1, n_samples=n_samples)
    traces = _reference_jit(setup, grid, recording, rtol, atol, friction_smoothing_m_s, max_steps)
    check_yield(traces, on_yield)
    return traces


@eqx.filter_jit
def _reference_jit(setup, grid, recording, rtol, atol, friction_smoothing_m_s, max_steps):
    model = build_model(setup)
    layout = _layout(setup, recording)
    scale = _scales(model)
    v0 = initial_velocity(model)
    zero = jnp.zeros(())
    y0 = _Solution(jnp.zeros_like(v0), v0 / scale.velocity_m_s, zero, zero, zero, zero)
    times = grid.sample_interval_s * jnp.arange(1, grid.n_samples + 1, dtype=jnp.float64)
    solution = dfx.diffeqsolve(
        dfx.ODETerm(_vector_field(model, friction_smoothing_m_s)),
        dfx.Dopri8(),
        t0=0.0,
        t1=grid.t_end_s,
        dt0=None,
        y0=y0,
        saveat=dfx.SaveAt(ts=times),
        stepsize_controller=dfx.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps,
    )
    ys = jax.tree_util.tree_map(lambda y, size: y * size, solution.ys, scale)
    records = jax.vmap(
        lambda y: _sample(model, y.displacement_m, y.velocity_m_s, y, layout, recording)
    )(ys)
    all_forces = jax.vmap(lambda y: chain_forces(model, y.displacement_m, y.velocity_m_s))(ys)
    records["max_force_n"] = jnp.concatenate(
        [jnp.max(all_forces.contact_total_n, axis=0), jnp.max(all_forces.wall_total_n)[None]]
    )
    return _assemble(setup, model, grid, recording, records)
