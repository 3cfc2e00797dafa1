"""Exact local and global sensitivities of physical observables to physical parameters.

Every derivative here is taken by automatic differentiation through the velocity-Verlet
core (`hertzchain.solve`): no finite differences. The run's time grid (step, sampling,
length) is fixed before differentiating, so a derivative is that of the simulator on that
grid, and central finite differences of the simulator on the same grid agree with it
(tests/test_sensitivity.py).

**Parameters** (`PARAMETERS`; SI units): `eta` (s), `mu`, `mu_star`, `striker_velocity`
(m/s), `striker_mass` (kg, at fixed striker radius), `wall_youngs` (Pa), `wall_poisson`,
`bead_radius` (m), `bead_density` (kg/m^3), `bead_youngs` (Pa), `bead_poisson`,
`sensor_beta`, `sensor_f0` (Hz), `precompression` (N, at a positive preload: at zero the
static overlap F^(2/3) makes the derivative singular), `yield_stress` (Pa) and
`yield_force` (N, the bead-bead contacts' yield force; all contacts' yield forces scale
together as the yield stress cubed) for elastic-plastic contacts (`plasticity=True`), and
`bead_masses` (kg, one per bead: N parameters, at fixed radii). The bead parameters act on
the beads, not on the striker; for a chain of unequal beads they scale every bead's value
in proportion to bead 1's.

**Observables** (`observable_names`), with `CH` one of `contact_K`, `wall`, `sensor_K`:

- `CH_peak` (N): the peak of the incident pulse: the first local maximum of the trace above
  30 % of the trace's largest value (for `wall`: the largest value), refined by the
  parabola through the three samples around it. The parabola's vertex value is a smooth
  function of the samples, so its derivative is that of the interpolated peak (the
  envelope theorem), not of an array index.
- `CH_peak_time` (s): the vertex time of that parabola.
- `CH_arrival` (s): the arrival time of the pulse: the time at which its leading edge
  crosses half its height above the static preload, linearly interpolated between the
  two samples around the crossing.
- `CH_duration` (s): the pulse duration $2\\tau$ of the paper's $F_m\\cos^6((t-t_0)/\\tau)$,
  estimated from the full width at half height as FWHM / arccos(2^{-1/6}) (exact for a
  cos^6 pulse; the discrete chain's pulse gives about 1.5 % less than a cos^6 fit).
- `speed_K_L` (m/s): pulse speed from contact K to contact L (K < L): the distance between
  the contact points at rest over the difference of their arrival times.
- `force_ratio_K`: wall peak over the incident peak at contact K (Eq. 5 of the paper).
- `dissipated_viscous`, `dissipated_friction`, `dissipated_plastic`, `dissipated_total`
  (J): energy dissipated by each mechanism by the end of the record.
- `trace_CH` (N, one value per sample): the whole force trace.

Elasticities are $\\partial\\ln O/\\partial\\ln p = (p/O)\\,\\partial O/\\partial p$. For a
parameter whose value is 0 the elasticity is 0; for an observable whose value is 0 it is
undefined and reported as None (JSON null). For whole traces the "elasticity" is
$p\\,\\partial F(t)/\\partial p$ divided by the trace's largest |F| (a pointwise ratio
would divide by zero before the pulse arrives).

Track friction is exact Coulomb stick-slip in the core (a clamped kick per step), so a
quantity is piecewise smooth at the scale of one time step: wherever beads stick, slip,
stop or touch again. Derivatives are exact on each piece; finite differences agree with
them to about 1e-3 along the incident pulse (tests), less well for quantities that sum
many late stick/slip events (the friction energy after the beads have stopped and
re-collided).

Forward or reverse mode is chosen from the Jacobian's shape: reverse (`jax.jacrev`) when
there are fewer observable values than parameter values (e.g. per-bead masses), forward
(`jax.jacfwd`) otherwise.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .chain import ChainSetup
from .integrate import Recording, solve
from .atomic import json_ready
from .progress import Progress
from .theory import COS6_HALF_WIDTH
from .timegrid import DEFAULT_STEPS_PER_CONTACT, TimeGrid, choose_time_grid
from .traces import Traces

# --------------------------------------------------------------------------- parameters


class Parameter(NamedTuple):
    """A physical parameter of a `ChainSetup` that sensitivities can be taken against.

    **Fields:** `name` (command-line name), `unit` (SI unit, "" if dimensionless),
    `meaning`, `get(setup) -> array` and `set(setup, value) -> setup` (pure, differentiable),
    `per_bead` (one value per bead).
    """

    name: str
    unit: str
    meaning: str
    get: Callable
    set: Callable
    per_bead: bool = False


def _field(name: str) -> Callable:
    return lambda setup: getattr(setup, name)


def _setter(name: str):
    return lambda setup, value: eqx.tree_at(
        lambda s: getattr(s, name), setup, jnp.asarray(value, dtype=jnp.float64)
    )


def _bead_scalar_get(name: str):
    return lambda setup: getattr(setup, name)[0]


def _bead_scalar_set(name: str):
    def set_value(setup, value):
        old = getattr(setup, name)
        return eqx.tree_at(lambda s: getattr(s, name), setup, old * (value / old[0]))

    return set_value


def _sphere_volume(radius_m):
    return 4.0 / 3.0 * jnp.pi * radius_m**3


def _set_bead_masses(setup, mass_kg):
    return eqx.tree_at(
        lambda s: s.bead_density_kg_m3, setup, mass_kg / _sphere_volume(setup.bead_radius_m)
    )


def _set_striker_mass(setup, mass_kg):
    return eqx.tree_at(
        lambda s: s.striker_density_kg_m3, setup, mass_kg / _sphere_volume(setup.striker_radius_m)
    )


def _set_yield_force(setup, force_n):
    current = setup.contact_yield_force_n()[1 if setup.n_beads > 1 else 0]
    stress = setup.bead_yield_stress_pa * (force_n / current) ** (1.0 / 3.0)
    return eqx.tree_at(lambda s: s.bead_yield_stress_pa, setup, stress)


def _scalar(name, field, unit, meaning) -> Parameter:
    return Parameter(name, unit, meaning, _field(field), _setter(field))


def _bead(name, field, unit, meaning) -> Parameter:
    return Parameter(name, unit, meaning, _bead_scalar_get(field), _bead_scalar_set(field))


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        _scalar("eta", "eta_s", "s", "viscoelastic time eta of F_v = eta kappa d(delta^3/2)/dt"),
        _scalar("mu", "mu", "", "track friction coefficient (force mu m g)"),
        _scalar("mu_star", "mu_star", "", "thwarted-rotation friction, kappa* = (1+mu*) kappa"),
        _scalar("striker_velocity", "striker_velocity_m_s", "m/s", "impact velocity"),
        Parameter(
            "striker_mass", "kg", "striker mass at fixed striker radius",
            lambda s: s.striker_mass_kg, _set_striker_mass,
        ),
        _scalar("wall_youngs", "wall_youngs_pa", "Pa", "Young's modulus of the wall"),
        _scalar("wall_poisson", "wall_poisson", "", "Poisson ratio of the wall"),
        _bead("bead_radius", "bead_radius_m", "m", "bead radius (every bead; striker unchanged)"),
        _bead("bead_density", "bead_density_kg_m3", "kg/m^3", "bead density (every bead)"),
        _bead("bead_youngs", "bead_youngs_pa", "Pa", "bead Young's modulus (every bead)"),
        _bead("bead_poisson", "bead_poisson", "", "bead Poisson ratio (every bead)"),
        _scalar("sensor_beta", "sensor_beta", "", "embedded sensor mass ratio beta"),
        _scalar("sensor_f0", "sensor_f0_hz", "Hz", "embedded sensor resonance f0"),
        _scalar("precompression", "precompression_n", "N", "static preload (> 0)"),
        _scalar("yield_stress", "bead_yield_stress_pa", "Pa",
                "bead yield stress of the elastic-plastic contacts (plasticity=True)"),
        Parameter(
            "yield_force", "N", "yield force of the bead-bead contacts (plasticity=True; "
            "all contacts' yield forces scale together, F_Y ~ yield stress^3)",
            lambda s: s.contact_yield_force_n()[1 if s.n_beads > 1 else 0], _set_yield_force,
        ),
        Parameter(
            "bead_masses", "kg", "mass of each bead at fixed radius (N parameters)",
            lambda s: s.bead_mass_kg, _set_bead_masses, per_bead=True,
        ),
    )
}


def _check_params(setup: ChainSetup, params: Sequence[str]) -> tuple[str, ...]:
    params = tuple(params)
    if not params:
        raise ValueError(f"params: give at least one parameter; valid: {', '.join(PARAMETERS)}.")
    for name in params:
        if name not in PARAMETERS:
            raise ValueError(
                f"params: unknown parameter {name!r}; valid parameters: {', '.join(PARAMETERS)}."
            )
    if len(set(params)) != len(params):
        raise ValueError(f"params: a parameter is listed twice: {params}.")
    for name in params:
        value = np.asarray(PARAMETERS[name].get(setup), dtype=float)
        if not np.all(np.isfinite(value)):
            raise ValueError(
                f"params: {name} is {value.tolist()} in this setup; its sensitivity is not defined "
                "(an infinitely stiff wall does not respond to its modulus): give a finite value."
            )
        if name.startswith("sensor_") and not setup.sensor_beads:
            raise ValueError(f"params: {name} needs an embedded sensor (sensor_beads is empty).")
        if name in ("yield_stress", "yield_force") and not setup.plasticity:
            raise ValueError(
                f"params: {name} acts only on elastic-plastic contacts; build the setup with "
                "plasticity=True (the elastic model only checks the yield force)."
            )
        if name == "precompression" and not float(setup.precompression_n) > 0:
            raise ValueError(
                "params: the sensitivity to precompression is singular at zero preload (the "
                "static overlap grows as F^(2/3)); evaluate it at a positive precompression_n."
            )
        if name == "wall_youngs" or name == "wall_poisson":
            if setup.end != "wall":
                raise ValueError(f"params: {name} needs a wall (this chain has a free end).")
    return params


def parameter_values(setup: ChainSetup, params: Sequence[str]) -> dict[str, jax.Array]:
    """The current values of `params` in `setup` (scalars, or (N,) for per-bead ones), SI."""
    return {name: jnp.asarray(PARAMETERS[name].get(setup)) for name in params}


def with_parameters(setup: ChainSetup, values: Mapping[str, jax.Array]) -> ChainSetup:
    """`setup` with the named parameters set to `values` (pure and differentiable)."""
    for name, value in values.items():
        setup = PARAMETERS[name].set(setup, value)
    return setup


# -------------------------------------------------------------------------- observables

_CHANNEL = r"(contact_\d+|wall|sensor_\d+)"
_PULSE = re.compile(rf"^{_CHANNEL}_(peak|peak_time|arrival|duration)$")
_TRACE = re.compile(rf"^trace_{_CHANNEL}$")
_SPEED = re.compile(r"^speed_(\d+)_(\d+)$")
_RATIO = re.compile(r"^force_ratio_(\d+)$")
_DISSIPATED = ("dissipated_viscous", "dissipated_friction", "dissipated_plastic", "dissipated_total")

OBSERVABLE_FORMS = (
    "contact_K_peak, wall_peak, sensor_K_peak (N)",
    "contact_K_peak_time, contact_K_arrival, contact_K_duration (s; also for wall, sensor_K)",
    "speed_K_L (m/s, K < L)",
    "force_ratio_K (wall peak / contact K peak)",
    "dissipated_viscous, dissipated_friction, dissipated_plastic, dissipated_total (J)",
    "trace_contact_K, trace_wall, trace_sensor_K (N per sample)",
)
_UNITS = {"peak": "N", "peak_time": "s", "arrival": "s", "duration": "s"}
# The incident pulse: first local maximum above this fraction of the trace's maximum.
_DETECT_FRACTION = 0.3


class Observable(NamedTuple):
    """A parsed observable: `name`, `kind`, the `channels` it reads, its `unit`."""

    name: str
    kind: str
    channels: tuple[str, ...]
    unit: str
    is_trace: bool = False


def _channel_error(setup: ChainSetup, name: str, channel: str) -> str | None:
    if channel == "wall":
        return None if setup.end == "wall" else f"{name}: this chain has a free end, no wall."
    kind, number = channel.split("_")
    k = int(number)
    if kind == "contact" and not 0 <= k < setup.n_beads:
        return (
            f"{name}: contact {k} is not in the chain (contacts are 0..{setup.n_beads - 1}; "
            "contact K is between bead K and K+1)."
        )
    if kind == "sensor" and k not in setup.sensor_beads:
        return (
            f"{name}: bead {k} has no embedded sensor (sensor beads: "
            f"{list(setup.sensor_beads) or 'none'}; add it with sensor_beads / --sensor-beads)."
        )
    return None


def parse_observable(setup: ChainSetup, name: str) -> Observable:
    """Parse and check an observable name against `setup`; `ValueError` lists the valid forms."""
    if match := _PULSE.match(name):
        obs = Observable(name, match.group(2), (match.group(1),), _UNITS[match.group(2)])
    elif match := _TRACE.match(name):
        obs = Observable(name, "trace", (match.group(1),), "N", is_trace=True)
    elif match := _SPEED.match(name):
        k, l = int(match.group(1)), int(match.group(2))
        if not k < l:
            raise ValueError(f"{name}: speed_K_L needs K < L (pulse travels towards the wall).")
        obs = Observable(name, "speed", (f"contact_{k}", f"contact_{l}"), "m/s")
    elif match := _RATIO.match(name):
        obs = Observable(name, "ratio", ("wall", f"contact_{match.group(1)}"), "")
    elif name in _DISSIPATED:
        obs = Observable(name, name, (), "J")
    else:
        raise ValueError(
            f"unknown observable {name!r}; valid forms: " + "; ".join(OBSERVABLE_FORMS) + "."
        )
    for channel in obs.channels:
        if message := _channel_error(setup, name, channel):
            raise ValueError(message)
    return obs


def observable_names(setup: ChainSetup) -> tuple[str, ...]:
    """Every scalar observable name valid for `setup` (traces and speeds excluded)."""
    channels = [f"contact_{k}" for k in range(setup.n_beads)]
    channels += [f"sensor_{b}" for b in setup.sensor_beads]
    channels += ["wall"] if setup.end == "wall" else []
    names = [f"{c}_{kind}" for c in channels for kind in _UNITS]
    if setup.end == "wall":
        names += [f"force_ratio_{k}" for k in range(setup.n_beads)]
    return tuple(names) + _DISSIPATED


def _recording(observables: Sequence[Observable]) -> Recording:
    contacts = sorted(
        {int(c.split("_")[1]) for o in observables for c in o.channels if c.startswith("contact_")}
    )
    return Recording(contacts=tuple(contacts))


class _Pulse(NamedTuple):
    peak: jax.Array
    peak_time: jax.Array
    arrival: jax.Array
    trailing: jax.Array
    found_peak: jax.Array
    found_arrival: jax.Array
    found_trailing: jax.Array


def _pulse(force_n, dt_s: float, baseline_n, scale_n, use_global_max: bool) -> _Pulse:
    """Peak, peak time and half-height crossings of the incident pulse of one trace.

    Separate from `pulses.first_peak` on purpose: it runs inside the jitted and
    differentiated observable function, so it never raises and flags what it cannot find
    instead; it measures from the precompression baseline and takes the first strict local
    maximum above 30 % of the pulse height. Its vertex is `pulses.refine_peak`'s three-point
    parabola (unclipped: at a local maximum the offset is within half a sample), with a
    safe denominator where the pulse is not found, so that flagged values stay finite.
    """
    y = force_n
    ys = jax.lax.stop_gradient(y)
    n = y.shape[0]
    index = jnp.arange(n)
    time = (index + 1) * dt_s
    top = jnp.max(ys)
    height_ok = top - baseline_n > 1e-6 * scale_n
    if use_global_max:
        i = jnp.argmax(ys)
        found = (i > 0) & (i < n - 1)
    else:
        local = (ys[1:-1] >= ys[:-2]) & (ys[1:-1] > ys[2:])
        local &= ys[1:-1] - baseline_n > _DETECT_FRACTION * (top - baseline_n)
        found = jnp.any(local)
        i = jnp.argmax(local) + 1
    i = jnp.clip(i, 1, n - 2)
    y0, y1, y2 = y[i - 1], y[i], y[i + 1]
    curvature = y0 - 2.0 * y1 + y2
    found = found & height_ok & (jax.lax.stop_gradient(curvature) < 0)
    safe = jnp.where(found, curvature, -1.0)
    offset = 0.5 * (y0 - y2) / safe
    peak = y1 - 0.25 * (y0 - y2) * offset
    peak_time = time[i] + offset * dt_s

    level = baseline_n + 0.5 * (peak - baseline_n)
    level_s = jax.lax.stop_gradient(level)
    below = ys < level_s
    j = jnp.max(jnp.where(below & (index <= i), index, -1))
    found_arrival = found & (j >= 0)
    j = jnp.clip(j, 0, n - 2)
    rise = jnp.where(found_arrival, y[j + 1] - y[j], 1.0)
    arrival = time[j] + dt_s * (level - y[j]) / rise
    k = jnp.min(jnp.where(below & (index >= i), index, n))
    found_trailing = found_arrival & (k < n)
    k = jnp.clip(k, 1, n - 1)
    fall = jnp.where(found_trailing, y[k] - y[k - 1], -1.0)
    trailing = time[k - 1] + dt_s * (level - y[k - 1]) / fall
    return _Pulse(peak, peak_time, arrival, trailing, found, found_arrival, found_trailing)


def _contact_distance_m(setup: ChainSetup, k: int, l: int):
    """Distance at rest between the contact points K and L (K < L), m."""
    return 2.0 * jnp.sum(setup.bead_radius_m[k:l])


def evaluate_observables(
    setup: ChainSetup, traces: Traces, observables: Sequence[Observable], sample_interval_s: float
) -> tuple[dict[str, jax.Array], dict[str, jax.Array]]:
    """Values and validity flags of `observables` from a run of `setup` (jit/vmap/grad safe).

    A flag is False where the observable does not exist in the run (no pulse, a pulse that
    has not arrived or not passed before the end of the record).
    """
    baseline = setup.precompression_n
    scale = jax.lax.stop_gradient(
        jnp.max(jnp.stack([jnp.max(jnp.abs(f - baseline)) for f in traces.forces_n.values()]))
    )
    pulses: dict[str, _Pulse] = {}

    def pulse(channel: str) -> _Pulse:
        if channel not in pulses:
            pulses[channel] = _pulse(
                traces.forces_n[channel], sample_interval_s, baseline, scale, channel == "wall"
            )
        return pulses[channel]

    values, valid = {}, {}
    true = jnp.asarray(True)
    for obs in observables:
        if obs.kind in ("peak", "peak_time"):
            p = pulse(obs.channels[0])
            values[obs.name], valid[obs.name] = getattr(p, obs.kind), p.found_peak
        elif obs.kind == "arrival":
            p = pulse(obs.channels[0])
            values[obs.name], valid[obs.name] = p.arrival, p.found_arrival
        elif obs.kind == "duration":
            p = pulse(obs.channels[0])
            values[obs.name] = (p.trailing - p.arrival) / COS6_HALF_WIDTH
            valid[obs.name] = p.found_trailing
        elif obs.kind == "speed":
            a, b = pulse(obs.channels[0]), pulse(obs.channels[1])
            k, l = (int(c.split("_")[1]) for c in obs.channels)
            gap = b.arrival - a.arrival
            ok = a.found_arrival & b.found_arrival & (jax.lax.stop_gradient(gap) > 0)
            values[obs.name] = _contact_distance_m(setup, k, l) / jnp.where(ok, gap, 1.0)
            valid[obs.name] = ok
        elif obs.kind == "ratio":
            wall, incident = pulse("wall"), pulse(obs.channels[1])
            ok = wall.found_peak & incident.found_peak
            values[obs.name] = wall.peak / jnp.where(ok, incident.peak, 1.0)
            valid[obs.name] = ok
        elif obs.kind == "dissipated_viscous":
            values[obs.name], valid[obs.name] = traces.dissipated_viscous_j[-1], true
        elif obs.kind == "dissipated_friction":
            values[obs.name], valid[obs.name] = traces.dissipated_friction_j[-1], true
        elif obs.kind == "dissipated_plastic":
            values[obs.name], valid[obs.name] = traces.dissipated_plastic_j[-1], true
        elif obs.kind == "dissipated_total":
            values[obs.name], valid[obs.name] = traces.dissipated_j[-1], true
        elif obs.kind == "trace":
            values[obs.name], valid[obs.name] = traces.forces_n[obs.channels[0]], true
        else:  # pragma: no cover - parse_observable admits only the kinds above
            raise AssertionError(obs.kind)
    return values, valid


def _invalid_reason(obs: Observable, t_end_s: float) -> str:
    channel = obs.channels[0] if obs.channels else ""
    what = {
        "peak": "no complete pulse (no local maximum inside the record)",
        "peak_time": "no complete pulse (no local maximum inside the record)",
        "arrival": "no pulse with a leading edge inside the record",
        "duration": "the pulse has not passed (no trailing half-height crossing) before the end",
        "speed": "the pulse has not arrived at both contacts",
        "ratio": "no complete pulse at the wall or at the contact",
    }.get(obs.kind, "not defined")
    return (
        f"{obs.name}: {what} at {channel or 'the channels'} within t_end = {t_end_s:.4g} s; "
        "lengthen the record (--t-end) or pick a contact the pulse reaches."
    )


# ----------------------------------------------------------------------- the Jacobian


def _size(tree) -> int:
    return sum(int(np.prod(jnp.shape(x))) for x in jax.tree_util.tree_leaves(tree))


def choose_mode(n_inputs: int, n_outputs: int) -> str:
    """'reverse' when the Jacobian has fewer rows (observable values) than columns
    (parameter values), else 'forward': each mode's cost grows with its own dimension."""
    return "reverse" if n_outputs < n_inputs else "forward"


def observable_function(
    setup: ChainSetup, params: Sequence[str], observables: Sequence[Observable], grid: TimeGrid
):
    """The function `values -> (observables, valid)` for a fixed time grid (differentiable).

    `values` is a dict param name -> value; the rest of `setup` is held fixed.
    """
    recording = _recording(observables)

    def fn(values, base=setup):
        changed = with_parameters(base, values)
        traces = solve(changed, grid, recording)
        return evaluate_observables(changed, traces, observables, grid.sample_interval_s)

    return fn


def _jacobian_fn(fn, mode: str):
    """(values, base) -> (observables, valid, jacobian) with the chosen AD mode."""

    def with_aux(values, base):
        out, valid = fn(values, base)
        return out, (out, valid)

    transform = jax.jacrev if mode == "reverse" else jax.jacfwd

    def run(values, base):
        jac, (out, valid) = transform(with_aux, has_aux=True)(values, base)
        return out, valid, jac

    return run


@eqx.filter_jit
def jacobian_at(values, setup, params, observables, grid, mode):
    """(observables, valid, jacobian) at parameter `values` (jitted; compiled once per
    structure of setup, parameter names, observables, grid and mode)."""
    fn = observable_function(setup, params, observables, grid)
    return _jacobian_fn(fn, mode)(values, setup)


# ------------------------------------------------------------------------------ results


def _elasticity(derivative, obs_value, param_value, is_trace: bool):
    """(p/O) dO/dp with the conventions of the module docstring (NumPy, NaN = undefined)."""
    d = np.asarray(derivative, dtype=float)
    p = np.asarray(param_value, dtype=float)
    o = np.asarray(obs_value, dtype=float)
    if is_trace:
        peak = np.max(np.abs(o), axis=-1, keepdims=True)
        # broadcast p over the trailing parameter axes of d (..., n_samples, *param_shape)
        scaled = d * p
        peak = peak.reshape(peak.shape + (1,) * p.ndim)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(peak > 0, scaled / peak, np.nan)
    o = o.reshape(o.shape + (1,) * (d.ndim - o.ndim))
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(p == 0, 0.0, d * p / o)
        return np.where((o == 0) & (p != 0), np.nan, e)


@dataclasses.dataclass(frozen=True)
class SensitivityResult:
    """Sensitivities of observables to parameters, at one setup or over a grid of setups.

    **Fields:**

    - `params`, `observables`: names; `units`: name -> SI unit.
    - `param_values`: name -> value, shape `grid_shape + param_shape`.
    - `values`: observable -> value, shape `grid_shape + obs_shape` (NaN where invalid).
    - `derivative`, `elasticity`: observable -> param -> array of shape
      `grid_shape + obs_shape + param_shape` (SI; NaN where the observable is invalid or the
      elasticity undefined).
    - `valid`: observable -> bool array of shape `grid_shape`; `messages`: why not, per
      invalid observable (first grid point where it fails).
    - `grid_axes`: swept parameter -> values (empty for one setup); `mode`: "forward" or
      "reverse"; `time_grid`: the fixed `TimeGrid`; `time_s`: the sample times.
    """

    params: tuple[str, ...]
    observables: tuple[str, ...]
    units: dict
    param_values: dict
    values: dict
    derivative: dict
    elasticity: dict
    valid: dict
    messages: dict
    grid_axes: dict
    mode: str
    time_grid: TimeGrid
    time_s: np.ndarray
    trace_observables: tuple[str, ...] = ()

    @property
    def grid_shape(self) -> tuple[int, ...]:
        return tuple(len(v) for v in self.grid_axes.values())

    def to_json(self) -> dict:
        """A JSON-ready dict (NaN/undefined -> None)."""

        def clean(x):
            return json_ready(np.asarray(x, dtype=float))

        data = {
            "grid": {"axes": list(self.grid_axes), "values": {k: clean(v) for k, v in self.grid_axes.items()}},
            "mode": self.mode,
            "time_grid": {
                "dt_s": self.time_grid.dt_s,
                "sample_interval_s": self.time_grid.sample_interval_s,
                "t_end_s": self.time_grid.t_end_s,
            },
            "params": {p: {"unit": self.units[p], "value": clean(self.param_values[p])} for p in self.params},
            "observables": {
                o: {"unit": self.units[o], "value": clean(self.values[o]),
                    "valid": np.asarray(self.valid[o]).tolist()}
                for o in self.observables
            },
            "derivative": {o: {p: clean(self.derivative[o][p]) for p in self.params} for o in self.observables},
            "elasticity": {o: {p: clean(self.elasticity[o][p]) for p in self.params} for o in self.observables},
            "conventions": {
                "derivative": "dO/dp in SI units of O per SI unit of p",
                "elasticity": "(p/O) dO/dp; 0 where p = 0; null where O = 0 or the observable "
                "does not exist; for trace_* observables p dF(t)/dp / max|F|",
            },
        }
        if self.messages:
            data["invalid"] = dict(self.messages)
        if self.trace_observables:
            data["time_s"] = np.asarray(self.time_s).tolist()
        return data

    def rows(self) -> list[dict]:
        """One row per (grid point, scalar observable, parameter component), for CSV."""
        rows = []
        axes = list(self.grid_axes)
        for point in np.ndindex(*self.grid_shape) if axes else [()]:
            where = {a: float(self.grid_axes[a][i]) for a, i in zip(axes, point)}
            for o in self.observables:
                if o in self.trace_observables:
                    continue
                for p in self.params:
                    d = np.asarray(self.derivative[o][p])[point]
                    e = np.asarray(self.elasticity[o][p])[point]
                    pv = np.asarray(self.param_values[p])[point]
                    for idx in np.ndindex(*d.shape) if d.ndim else [()]:
                        label = p + (f"[{idx[0] + 1}]" if idx else "")
                        rows.append({
                            **where,
                            "observable": o,
                            "observable_unit": self.units[o],
                            "observable_value": float(np.asarray(self.values[o])[point]),
                            "param": label,
                            "param_unit": self.units[p],
                            "param_value": float(pv[idx]),
                            "derivative": float(d[idx]),
                            "elasticity": float(e[idx]),
                        })
        return rows


def _prepare(setup, params, observables, sweep=None):
    params = _check_params(setup, params)
    if isinstance(observables, str):
        observables = [observables]
    parsed = tuple(parse_observable(setup, name) for name in observables)
    if not parsed:
        raise ValueError("observables: give at least one observable; valid forms: "
                         + "; ".join(OBSERVABLE_FORMS) + ".")
    if len({o.name for o in parsed}) != len(parsed):
        raise ValueError(f"observables: an observable is listed twice: {list(observables)}.")
    return params, parsed


def _units(params, parsed) -> dict:
    units = {p: PARAMETERS[p].unit for p in params}
    units.update({o.name: o.unit for o in parsed})
    return units


def sensitivity(
    setup: ChainSetup,
    params: Sequence[str],
    observables: Sequence[str],
    *,
    t_end_s: float = 2.5e-3,
    sample_interval_s: float = 1e-6,
    dt_s: float | None = None,
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT,
    mode: str = "auto",
    grid: TimeGrid | None = None,
) -> SensitivityResult:
    """Exact derivatives and elasticities of `observables` with respect to `params`.

    **Arguments:**

    - `setup`: the chain (a single, unbatched `ChainSetup`).
    - `params`: names from `PARAMETERS` (e.g. `("eta", "mu", "wall_youngs")`).
    - `observables`: names (see the module docstring, e.g. `("wall_peak", "contact_6_peak")`).
    - `t_end_s`, `sample_interval_s`, `dt_s`, `steps_per_contact`: the run, as in `simulate`
      (or give a ready `grid`).
    - `mode`: "auto" (by the Jacobian's shape), "forward" or "reverse".

    **Returns:** `SensitivityResult`.

    **Raises:** `ValueError` for unknown names (the valid ones are listed), observables not
    in the chain, and observables that do not exist in the run (e.g. a pulse that never
    arrives within `t_end_s`).
    """
    params, parsed = _prepare(setup, params, observables)
    if grid is None:
        grid = choose_time_grid(setup, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                                dt_s=dt_s, steps_per_contact=steps_per_contact)
    values0 = parameter_values(setup, params)
    n_out = sum(grid.n_samples if o.is_trace else 1 for o in parsed)
    mode = _resolve_mode(mode, _size(values0), n_out)
    out, valid, jac = jacobian_at(values0, setup, params, parsed, grid, mode)
    for obs in parsed:
        if not bool(valid[obs.name]):
            raise ValueError(_invalid_reason(obs, grid.t_end_s))
    return _result(params, parsed, values0, out, valid, jac, {}, mode, grid, {})


def _resolve_mode(mode: str, n_in: int, n_out: int) -> str:
    if mode == "auto":
        return choose_mode(n_in, n_out)
    if mode not in ("forward", "reverse"):
        raise ValueError(f"mode must be 'auto', 'forward' or 'reverse', got {mode!r}.")
    return mode


def _result(params, parsed, param_values, out, valid, jac, axes, mode, grid, messages):
    derivative, elasticity, values = {}, {}, {}
    grid_ndim = len(axes)
    for obs in parsed:
        ok = np.asarray(valid[obs.name], dtype=bool)
        v = np.asarray(out[obs.name], dtype=float)
        mask = ok.reshape(ok.shape + (1,) * (v.ndim - grid_ndim))
        values[obs.name] = np.where(mask, v, np.nan)
        derivative[obs.name], elasticity[obs.name] = {}, {}
        for p in params:
            d = np.asarray(jac[obs.name][p], dtype=float)
            dmask = ok.reshape(ok.shape + (1,) * (d.ndim - grid_ndim))
            d = np.where(dmask, d, np.nan)
            derivative[obs.name][p] = d
            elasticity[obs.name][p] = _elasticity(d, values[obs.name], param_values[p], obs.is_trace)
    return SensitivityResult(
        params=tuple(params),
        observables=tuple(o.name for o in parsed),
        units=_units(params, parsed),
        param_values={p: np.asarray(param_values[p], dtype=float) for p in params},
        values=values,
        derivative=derivative,
        elasticity=elasticity,
        valid={o.name: np.asarray(valid[o.name], dtype=bool) for o in parsed},
        messages=messages,
        grid_axes={k: np.asarray(v, dtype=float) for k, v in axes.items()},
        mode=mode,
        time_grid=grid,
        time_s=grid.sample_interval_s * np.arange(1, grid.n_samples + 1),
        trace_observables=tuple(o.name for o in parsed if o.is_trace),
    )


# ------------------------------------------------------------------------------ sweeps


def _check_axes(setup: ChainSetup, axes: Mapping[str, Sequence[float]]) -> dict[str, np.ndarray]:
    if not axes:
        raise ValueError("sweep: give at least one parameter to sweep, e.g. "
                         "{'striker_velocity': [0.1, 0.3], 'wall_youngs': [5e9, 2.03e11]}.")
    out = {}
    for name, values in axes.items():
        if name not in PARAMETERS or PARAMETERS[name].per_bead:
            scalar = [n for n, p in PARAMETERS.items() if not p.per_bead]
            raise ValueError(f"sweep: cannot sweep {name!r}; sweepable parameters: {', '.join(scalar)}.")
        array = np.asarray(values, dtype=float).ravel()
        if array.size == 0 or not np.all(np.isfinite(array)):
            raise ValueError(f"sweep: {name} needs finite values, got {list(values)}.")
        out[name] = array
    _check_params(setup, tuple(out))
    return out


def _batched_values(axes: dict[str, np.ndarray]) -> dict[str, jax.Array]:
    mesh = np.meshgrid(*axes.values(), indexing="ij")
    return {name: jnp.asarray(m.ravel()) for name, m in zip(axes, mesh)}


def _grid_for_batch(setup, points: dict[str, jax.Array], **run) -> TimeGrid:
    batched = jax.vmap(lambda v: with_parameters(setup, v))(points)
    return choose_time_grid(batched, **run)


@eqx.filter_jit
def _jacobian_batch(batch, setup, params, observables, grid, mode):
    """`jacobian_at` vmapped over setups that differ in the parameters of `batch` (name ->
    (n,) values); also returns the parameter values of every setup."""
    fn = observable_function(setup, params, observables, grid)
    jac_fn = _jacobian_fn(fn, mode)

    def one(point):
        base = with_parameters(setup, point)
        values = parameter_values(base, params)
        return jac_fn(values, base) + (values,)

    return jax.vmap(one)(batch)


def _chunked(run, points: dict[str, jax.Array], chunk_size: int, label: str, progress: bool):
    """Apply a vmapped `run` to the points in equal chunks (padded), with progress."""
    size = int(next(iter(points.values())).shape[0])
    chunk = max(1, min(chunk_size, size))
    meter = Progress(size, label) if progress else None
    pieces = []
    for start in range(0, size, chunk):
        stop = min(start + chunk, size)
        idx = np.arange(start, start + chunk).clip(max=stop - 1)  # pad with the last point
        part = run({k: v[idx] for k, v in points.items()})
        part = jax.tree_util.tree_map(lambda x, n=stop - start: np.asarray(x)[:n], part)
        pieces.append(part)
        if meter:
            meter.advance(stop - start)
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *pieces)


def sensitivity_sweep(
    setup: ChainSetup,
    params: Sequence[str],
    observables: Sequence[str],
    sweep: Mapping[str, Sequence[float]],
    *,
    t_end_s: float = 2.5e-3,
    sample_interval_s: float = 1e-6,
    dt_s: float | None = None,
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT,
    mode: str = "auto",
    chunk_size: int = 64,
    progress: bool = True,
) -> SensitivityResult:
    """`sensitivity` over the outer product of swept parameter values, vmapped in chunks.

    **Arguments:** as `sensitivity`, plus `sweep`: parameter name -> values (the grid is
    their outer product, e.g. `{"striker_velocity": [...], "wall_youngs": [...]}`), and
    `chunk_size` setups per vmapped call. One time step, fine enough for every grid point,
    is used for all. Observables must be scalars (no `trace_*`).

    **Returns:** `SensitivityResult` with `grid_axes` and leading grid axes on every array.
    Observables that do not exist at some grid points (a pulse that has not arrived) are
    NaN there, flagged in `valid` and explained in `messages`; an observable that exists
    nowhere on the grid raises `ValueError`.
    """
    params, parsed = _prepare(setup, params, observables)
    if any(o.is_trace for o in parsed):
        raise ValueError("sweep: whole-trace observables (trace_*) are not swept; use scalar ones.")
    axes = _check_axes(setup, sweep)
    points = _batched_values(axes)
    grid = _grid_for_batch(setup, points, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                           dt_s=dt_s, steps_per_contact=steps_per_contact)
    n_in = _size(parameter_values(setup, params))
    mode = _resolve_mode(mode, n_in, len(parsed))
    run = lambda batch: _jacobian_batch(batch, setup, params, parsed, grid, mode)  # noqa: E731
    out, valid, jac, pvals = _chunked(run, points, chunk_size, "sensitivity sweep (setups)", progress)
    shape = tuple(len(v) for v in axes.values())
    reshape = lambda x: np.asarray(x).reshape(shape + np.asarray(x).shape[1:])  # noqa: E731
    out, valid, jac, pvals = (jax.tree_util.tree_map(reshape, t) for t in (out, valid, jac, pvals))
    messages = {}
    for obs in parsed:
        ok = np.asarray(valid[obs.name])
        if not ok.any():
            raise ValueError(_invalid_reason(obs, grid.t_end_s) + " (at every grid point)")
        if not ok.all():
            first = np.argwhere(~ok)[0]
            where = ", ".join(f"{a} = {axes[a][i]:g}" for a, i in zip(axes, first))
            messages[obs.name] = (
                f"undefined at {int((~ok).sum())} of {ok.size} grid points (first: {where}): "
                + _invalid_reason(obs, grid.t_end_s)
            )
    return _result(params, parsed, pvals, out, valid, jac, axes, mode, grid, messages)


# ------------------------------------------------------------------ global sensitivity


@dataclasses.dataclass(frozen=True)
class GlobalSensitivity:
    """Derivative-based global sensitivity measures over a sampled parameter box.

    **Fields:** `box` (param -> (low, high), SI), `n_samples` (points sampled; `n_valid`
    per observable where it exists), `mean_squared_elasticity` and
    `mean_abs_elasticity` (observable -> param -> value: $E[(\\partial\\ln O/\\partial\\ln
    p)^2]$ and $E|\\cdot|$ over the box), `ranking` (observable -> params from most to least
    influential), `samples` (the underlying `SensitivityResult`, grid axis "sample").
    """

    box: dict
    n_samples: int
    n_valid: dict
    mean_squared_elasticity: dict
    mean_abs_elasticity: dict
    ranking: dict
    samples: SensitivityResult

    def to_json(self) -> dict:
        return {
            "method": "derivative-based global sensitivity: mean over a Latin-hypercube sample "
            "of the box of the squared elasticity (p/O dO/dp)^2",
            "box": {k: list(map(float, v)) for k, v in self.box.items()},
            "n_samples": self.n_samples,
            "n_valid": self.n_valid,
            "mean_squared_elasticity": self.mean_squared_elasticity,
            "mean_abs_elasticity": self.mean_abs_elasticity,
            "ranking": self.ranking,
        }


def global_sensitivity(
    setup: ChainSetup,
    observables: Sequence[str],
    box: Mapping[str, tuple[float, float]],
    *,
    params: Sequence[str] | None = None,
    n_samples: int = 64,
    seed: int = 0,
    t_end_s: float = 2.5e-3,
    sample_interval_s: float = 1e-6,
    dt_s: float | None = None,
    chunk_size: int = 64,
    progress: bool = True,
) -> GlobalSensitivity:
    """Mean squared elasticities of `observables` over a Latin-hypercube sample of `box`.

    **Arguments:** `box`: parameter -> (low, high) in SI (uniform sampling); `params`: the
    parameters to rank (default: those of the box); `n_samples` points, drawn with `seed`;
    run options as `sensitivity`.

    **Returns:** `GlobalSensitivity` (grid points where an observable does not exist are
    left out of its means and counted in `n_valid`).
    """
    from scipy.stats import qmc

    if not box:
        raise ValueError("box: give at least one parameter range, e.g. {'eta': (0, 3e-6)}.")
    for name, bounds in box.items():
        if len(bounds) != 2 or not float(bounds[0]) <= float(bounds[1]):
            raise ValueError(f"box: {name} needs (low, high) with low <= high, got {bounds}.")
    if n_samples < 2:
        raise ValueError(f"n_samples must be at least 2, got {n_samples}.")
    params = tuple(box) if params is None else tuple(params)
    names = list(box)
    unit = qmc.LatinHypercube(d=len(names), seed=seed).random(n_samples)
    low = np.array([float(box[n][0]) for n in names])
    high = np.array([float(box[n][1]) for n in names])
    points = low + unit * (high - low)
    params, parsed = _prepare(setup, params, observables)
    _check_axes(setup, {n: points[:, i] for i, n in enumerate(names)})
    if any(o.is_trace for o in parsed):
        raise ValueError("global sensitivity: whole-trace observables (trace_*) are not supported.")
    batch = {n: jnp.asarray(points[:, i]) for i, n in enumerate(names)}
    grid = _grid_for_batch(setup, batch, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                           dt_s=dt_s)
    mode = _resolve_mode("auto", _size(parameter_values(setup, params)), len(parsed))
    run = lambda chunk: _jacobian_batch(chunk, setup, params, parsed, grid, mode)  # noqa: E731
    out, valid, jac, pvals = _chunked(run, batch, chunk_size, "global sensitivity (samples)", progress)
    axes = {"sample": np.arange(n_samples, dtype=float)}
    messages = {}
    for obs in parsed:
        ok = np.asarray(valid[obs.name])
        if not ok.any():
            raise ValueError(_invalid_reason(obs, grid.t_end_s) + " (anywhere in the box)")
        if not ok.all():
            messages[obs.name] = f"undefined at {int((~ok).sum())} of {n_samples} samples: " + \
                _invalid_reason(obs, grid.t_end_s)
    samples = _result(params, parsed, pvals, out, valid, jac, axes, mode, grid, messages)
    msq, mabs, ranking, n_valid = {}, {}, {}, {}
    for obs in samples.observables:
        ok = samples.valid[obs]
        n_valid[obs] = int(ok.sum())
        msq[obs], mabs[obs] = {}, {}
        for p in params:
            e = samples.elasticity[obs][p][ok]
            e = e.reshape(e.shape[0], -1)
            msq[obs][p] = json_ready(np.mean(np.sum(e**2, axis=1)))
            mabs[obs][p] = json_ready(np.mean(np.sqrt(np.sum(e**2, axis=1))))
        ranking[obs] = sorted(params, key=lambda p: -(msq[obs][p] or 0.0))
    return GlobalSensitivity(
        box={k: (float(v[0]), float(v[1])) for k, v in box.items()},
        n_samples=n_samples,
        n_valid=n_valid,
        mean_squared_elasticity=msq,
        mean_abs_elasticity=mabs,
        ranking=ranking,
        samples=samples,
    )


# ------------------------------------------------------------------------------ plots


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_elasticities(result: SensitivityResult):
    """Bar chart of the elasticities of each scalar observable (one setup)."""
    plt = _plt()
    scalars = [o for o in result.observables if o not in result.trace_observables]
    labels, blocks = [], []
    for p in result.params:
        n = int(np.prod(result.param_values[p].shape))
        labels += [p] if n == 1 else [f"{p}[{i + 1}]" for i in range(n)]
    figure, ax = plt.subplots(figsize=(max(6, 0.5 * len(labels) * max(len(scalars), 1) ** 0.5 + 4), 4.5))
    width = 0.8 / max(len(scalars), 1)
    x = np.arange(len(labels))
    for i, o in enumerate(scalars):
        row = np.concatenate([np.ravel(result.elasticity[o][p]) for p in result.params])
        blocks.append(row)
        ax.bar(x + (i - (len(scalars) - 1) / 2) * width, np.nan_to_num(row), width, label=o)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks(x, labels, rotation=45 if len(labels) > 6 else 0, ha="right" if len(labels) > 6 else "center")
    ax.set_ylabel("elasticity  ∂ln O / ∂ln p  (dimensionless)")
    ax.set_title("local sensitivities")
    if scalars:
        ax.legend(fontsize=8)
    figure.tight_layout()
    return figure


def plot_trace_sensitivities(result: SensitivityResult):
    """Derivative traces p dF(t)/dp (N) of every trace observable, one panel each."""
    plt = _plt()
    traces = result.trace_observables
    figure, axes = plt.subplots(len(traces), 1, figsize=(8, 2.8 * len(traces)), squeeze=False)
    t_ms = result.time_s * 1e3
    for ax, o in zip(axes[:, 0], traces):
        for p in result.params:
            d = np.asarray(result.derivative[o][p])
            pv = np.asarray(result.param_values[p])
            if d.ndim > 1:
                continue
            ax.plot(t_ms, d * (pv if np.all(pv != 0) else 1.0), label=p + ("" if np.all(pv != 0) else " (per unit)"))
        ax.set_ylabel(f"p ∂F/∂p (N)\n{o}")
        ax.legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time since impact (ms)")
    figure.tight_layout()
    return figure


def plot_sweep(result: SensitivityResult):
    """Heat maps (two swept parameters) or curves (one) of every elasticity of the sweep."""
    plt = _plt()
    axes_names = list(result.grid_axes)
    obs, params = result.observables, [p for p in result.params if result.param_values[p].ndim == len(axes_names)]
    figure, grid = plt.subplots(len(obs), len(params), figsize=(3.6 * len(params) + 1, 3.0 * len(obs)),
                                squeeze=False)
    for i, o in enumerate(obs):
        for j, p in enumerate(params):
            ax = grid[i, j]
            e = np.asarray(result.elasticity[o][p], dtype=float)
            if len(axes_names) == 1:
                x = result.grid_axes[axes_names[0]]
                ax.plot(x, e, "o-")
                ax.set_xscale("log" if np.all(x > 0) else "linear")
                ax.set_xlabel(_axis_label(result, axes_names[0]))
                ax.axhline(0, color="k", lw=0.6)
            elif len(axes_names) == 2:
                x, y = (result.grid_axes[a] for a in axes_names)
                limit = np.nanmax(np.abs(e)) if np.any(np.isfinite(e)) else 1.0
                mesh = ax.pcolormesh(np.arange(len(y) + 1), np.arange(len(x) + 1), e, cmap="RdBu_r",
                                     vmin=-limit, vmax=limit, shading="flat")
                ax.set_xticks(np.arange(len(y)) + 0.5, [f"{v:.3g}" for v in y], fontsize=7, rotation=45)
                ax.set_yticks(np.arange(len(x)) + 0.5, [f"{v:.3g}" for v in x], fontsize=7)
                ax.set_xlabel(_axis_label(result, axes_names[1]))
                ax.set_ylabel(_axis_label(result, axes_names[0]))
                figure.colorbar(mesh, ax=ax, label="∂ln O/∂ln p")
            ax.set_title(f"{o} vs {p}", fontsize=9)
    figure.tight_layout()
    return figure


def _axis_label(result, name):
    unit = result.units.get(name) or PARAMETERS[name].unit
    return f"{name} ({unit})" if unit else name


def plot_global_ranking(result: GlobalSensitivity):
    """Ranking bars of the mean squared elasticities (log scale), one panel per observable."""
    plt = _plt()
    obs = list(result.mean_squared_elasticity)
    figure, axes = plt.subplots(1, len(obs), figsize=(4 * len(obs) + 1, 3.8), squeeze=False)
    for ax, o in zip(axes[0], obs):
        order = result.ranking[o]
        values = [result.mean_squared_elasticity[o][p] or 0.0 for p in order]
        ax.barh(np.arange(len(order))[::-1], np.maximum(values, 1e-30), color="tab:blue")
        ax.set_yticks(np.arange(len(order))[::-1], order)
        ax.set_xscale("log")
        ax.set_xlabel("E[(∂ln O/∂ln p)²] over the box")
        ax.set_title(o, fontsize=9)
    figure.tight_layout()
    return figure
