"""The physical range of every `ChainSetup` value, the stability of the step, the size of a run.

One table (`RULES`) holds, for every numeric field of a setup, the values it may take (a
violation is a `ValueError` naming the field, the value and the fix) and the values a
measured chain plausibly has, with the units a user most likely meant when a value falls
outside them (`eta_s = 2 s` -> "did you mean 2us?"). The same rules apply wherever a value
enters: `ChainSetup` construction with concrete values (`check_setup`), every value of a
sweep's grid before anything runs (`check_values`), and values typed by a user (command
line, experiment-file headers: `check_plausible`). Values traced under `jit`/`vmap`/`grad`
are not checked here (the solver's model checks those at run time).

`check_step_stability` refuses a time step that the damping makes unstable (the bound is
derived in `damping_rate_1_s`); `check_run_size` refuses, before it starts, a run whose
recorded samples exceed the machine's available memory or whose work exceeds
`MAX_BODY_STEPS`, unless the caller confirms it.
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np


class Rule(NamedTuple):
    """The allowed and plausible values of one setup field.

    **Fields:** `low`, `high` the allowed interval (SI), `low_open`/`high_open` whether an
    end is excluded, `infinite_ok` whether +inf is allowed (a rigid wall); `requirement` the
    allowed range in words; `meaning` what the field is; `unit` its SI unit;
    `plausible` the (low, high) interval of measured chains; `hints` (factor, suffix) pairs:
    a value v outside the plausible interval whose `v * factor` lies inside it was probably
    meant as `v<suffix>` (an empty suffix: the SI number `v * factor`).
    """

    low: float
    high: float
    low_open: bool
    high_open: bool
    infinite_ok: bool
    requirement: str
    meaning: str
    unit: str
    plausible: tuple[float, float]
    hints: tuple[tuple[float, str], ...] = ()


_MODULUS_HINTS = ((1e9, "GPa"), (1e6, "MPa"))
_POISSON = Rule(-1.0, 0.5, True, True, False, "in (-1, 0.5)", "a Poisson ratio", "", (-1.0, 0.5), ((0.01, ""),))


def _positive(requirement, meaning, unit, plausible, hints=(), infinite_ok=False):
    return Rule(0.0, math.inf, True, False, infinite_ok, requirement, meaning, unit, plausible, hints)


def _non_negative(requirement, meaning, unit, plausible, hints=()):
    return Rule(0.0, math.inf, False, False, False, requirement, meaning, unit, plausible, hints)


RULES: dict[str, Rule] = {
    "bead_radius_m": _positive("positive and finite (m)", "a bead radius", "m", (1e-5, 1.0), ((1e-3, "mm"),)),
    "bead_mass_kg": _positive("positive (kg)", "a bead mass", "kg", (1e-9, 1e3), ((1e-3, ""),)),
    "bead_density_kg_m3": _positive("positive (kg/m^3)", "a bead density", "kg/m^3", (100.0, 3e4), ((1e3, ""),)),
    "bead_youngs_pa": _positive("positive and finite (Pa)", "a Young's modulus", "Pa", (1e6, 2e12), _MODULUS_HINTS),
    "bead_poisson": _POISSON,
    "bead_yield_stress_pa": _positive("positive (Pa)", "a yield stress", "Pa", (1e6, 1e11), _MODULUS_HINTS,
                                      infinite_ok=True),
    "striker_radius_m": _positive("positive and finite (m)", "a striker radius", "m", (1e-5, 1.0),
                                  ((1e-3, "mm"),)),
    "striker_mass_kg": _positive("positive (kg)", "a striker mass", "kg", (1e-9, 1e3), ((1e-3, ""),)),
    "striker_density_kg_m3": _positive("positive", "a striker density", "kg/m^3", (100.0, 3e4), ((1e3, ""),)),
    "striker_youngs_pa": _positive("positive (Pa)", "a Young's modulus", "Pa", (1e6, 2e12), _MODULUS_HINTS),
    "striker_poisson": _POISSON,
    "striker_velocity_m_s": _positive("positive and finite (m/s; the striker moves towards bead 1)",
                                      "an impact velocity", "m/s", (1e-6, 100.0), ((1e-3, "mm/s"),)),
    "wall_youngs_pa": _positive("positive (Pa; inf = rigid)", "a wall's Young's modulus", "Pa", (1e5, math.inf),
                                _MODULUS_HINTS, infinite_ok=True),
    "wall_poisson": _POISSON,
    "eta_s": _non_negative("non-negative (s)", "viscoelastic damping (us scale)", "s", (0.0, 1e-3),
                           ((1e-6, "us"), (1e-9, "ns"))),
    "dashpot_n_s_m": _non_negative("non-negative (N s/m)", "a contact dashpot", "N s/m", (0.0, 1e5)),
    "contact_exponent": Rule(1.0, 3.0, False, False, False, "between 1 and 3 (Hertz: 1.5)",
                             "a contact-law exponent", "", (1.0, 3.0)),
    "exponent_reference_overlap_m": _positive("positive (m)", "a reference overlap", "m", (1e-9, 1e-3),
                                              ((1e-6, "um"),)),
    "mu": _non_negative("non-negative", "a track friction coefficient", "", (0.0, 2.0), ((0.01, ""),)),
    "mu_star": Rule(-1.0, math.inf, True, False, False, "greater than -1", "thwarted-rotation friction", "",
                    (-0.5, 10.0)),
    "precompression_n": _non_negative(">= 0 (N)", "a static preload", "N", (0.0, 1e6)),
    "gravity_m_s2": _non_negative(">= 0 (m/s^2)", "gravity", "m/s^2", (0.0, 100.0)),
    "sensor_beta": Rule(0.0, 1.0, True, True, False, "in (0, 1)", "a sensor mass ratio", "", (0.0, 1.0)),
    "sensor_f0_hz": _positive("positive (Hz)", "a sensor resonance", "Hz", (1.0, 1e9), ((1e3, "kHz"),)),
}

# Fields that matter only with embedded sensors (a setup without any keeps their defaults).
SENSOR_FIELDS = ("sensor_beta", "sensor_f0_hz")


def as_float64(value, name: str):
    """`value` as a float64 JAX array (SI units), or a ValueError naming the argument `name`
    where it is not a number."""
    import jax.numpy as jnp

    try:
        return jnp.asarray(value, dtype=jnp.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a number (SI units), got {value!r}.") from error


def is_concrete(value) -> bool:
    """True for a value with numbers (not a tracer of `jit`, `vmap` or `grad`)."""
    import jax

    return not isinstance(value, jax.core.Tracer)


def check_positive_parameters(owner: str, fields, *, zero_ok: bool = False) -> None:
    """Refuse a parameter that is not finite and > 0 (>= 0 where `zero_ok`), each element of
    an array.

    `owner`: the law's or model's name, for the message; `fields`: (name, value, unit)
    triples. Traced values (inside `jit`, `vmap`, `grad`) are left to the caller's run.
    """
    bound = ">= 0" if zero_ok else "> 0"
    for name, value, unit in fields:
        if is_concrete(value):
            array = np.asarray(value)
            if not bool(np.all(np.isfinite(array) & ((array >= 0.0) if zero_ok else (array > 0.0)))):
                raise ValueError(f"{owner}: {name} must be finite and {bound} ({unit}), got {value}.")


def _allowed(rule: Rule, array: np.ndarray) -> np.ndarray:
    above = array > rule.low if rule.low_open else array >= rule.low
    below = array < rule.high if rule.high_open else array <= rule.high
    finite = np.isfinite(array) | (rule.infinite_ok & (array == math.inf))
    return finite & above & below


def _shown(array: np.ndarray):
    return array.item() if array.size == 1 else array.tolist()


def unit_hint(name: str, value: float) -> str | None:
    """For a value outside the plausible range of field `name`: "did you mean ...?" naming the
    value in the unit the user probably meant, or None (plausible, or no likely unit)."""
    rule = RULES[name]
    low, high = rule.plausible
    if not math.isfinite(value) or low <= value <= high:
        return None
    for factor, suffix in rule.hints:
        scaled = value * factor
        if low < scaled <= high and scaled != 0:
            if suffix:
                return f"did you mean {value:g}{suffix}?"
            return f"did you mean {scaled:g} {rule.unit}?" if rule.unit else f"did you mean {scaled:g}?"
    return None


def check_values(name: str, values, *, where: str | None = None) -> None:
    """Raise `ValueError` naming `name` (and `where`, e.g. "--grid") if any concrete value
    lies outside the field's allowed range; traced values pass unchecked.

    The message gives the value, the allowed range and, when the value looks like another
    unit's, the value the user probably meant.
    """
    if name not in RULES or not is_concrete(values):
        return
    rule = RULES[name]
    array = np.asarray(values, dtype=float)
    label = f"{where}: {name}" if where else name
    if np.any(np.isnan(array)):
        raise ValueError(f"{label} contains NaN; give {rule.requirement}.")
    bad = ~_allowed(rule, array)
    if np.any(bad):
        hint = unit_hint(name, float(array[bad].ravel()[0]))
        raise ValueError(f"{label} must be {rule.requirement}, got {_shown(array)}." + (f" ({hint})" if hint else ""))


def check_plausible(name: str, values, *, where: str | None = None) -> None:
    """Like `check_values`, and also refuse values outside the plausible range of measured
    chains (for values a user typed: options, grids, file headers), with the unit hint."""
    check_values(name, values, where=where)
    if name not in RULES or not is_concrete(values):
        return
    rule = RULES[name]
    low, high = rule.plausible
    array = np.asarray(values, dtype=float).ravel()
    outside = array[(array < low) | (array > high)]
    if outside.size:
        value = float(outside[0])
        label = f"{where}: {name}" if where else name
        hint = unit_hint(name, value) or "check the sign and that the value is in SI units."
        unit = f" {rule.unit}" if rule.unit else ""
        raise ValueError(
            f"{label} = {value!r} is outside the plausible range [{low:g}, {high:g}]{unit} of {rule.meaning}: {hint}"
        )


def check_setup(setup) -> None:
    """Check every numeric field of a `ChainSetup` against `RULES` (concrete values only);
    the sensor fields only where the setup has sensors."""
    for name in RULES:
        if not hasattr(setup, name) or name in ("bead_mass_kg", "striker_mass_kg"):
            continue
        if name in SENSOR_FIELDS and not setup.sensor_beads:
            continue
        check_values(name, getattr(setup, name))


# -- stability of the velocity-Verlet step --------------------------------------------------

STABILITY_LIMIT = 1.0


def damping_rate_1_s(setup) -> float:
    """Upper bound of the chain's damping rate $\\lambda_{max}$ (largest eigenvalue of
    $M^{-1}C$), 1/s, for a setup (batched: the largest over the batch).

    The solver (`integrate.verlet_step`) evaluates the viscous force at the predicted velocity $v_n + \\Delta t\\,a_n$.
    On a pure damping mode $\\dot w = -\\lambda w$ this gives, in $(w, \\Delta t\\,a)$ and with
    $z = \\lambda\\Delta t$, the step matrix $[[1 - z/2, (1 - z)/2], [-z, -z]]$: trace
    $1 - 3z/2$, determinant $-z/2$. Its eigenvalues stay in the unit circle (Jury:
    $|\\det| < 1$, $1 \\pm \\mathrm{tr} + \\det > 0$) exactly for $0 \\le z < 1$, so the step is
    stable for $\\lambda_{max}\\,\\Delta t < 1$ (`STABILITY_LIMIT`); at $z = 1$ an eigenvalue
    reaches $-1$ and the velocities zigzag and grow from step to step.

    Each contact damps like a dashpot $c = \\gamma + \\tfrac32\\eta\\kappa\\,\\delta^{1/2}$
    (`contact.contact_force`), taken at the overlap of the largest force the run can produce
    (2.5 times the striker's first collision force plus the preload, as for the choice of
    the step). $\\lambda_{max}$ is bounded by Gershgorin's row sums of $M^{-1}C$:
    $(2\\sum_{internal} c + c_{wall})/m_i$ for each body i (sensor springs undamped). The
    bound is tight for a dashpot (5 steel beads on a steel wall: at 0.9 of the bound the wall's
    peak force is within 0.3 % of a step four times smaller, at 1.2 of it 11 % off, at 1.5 of it
    53 %, at 4 of it 2400 times). For `eta_s` it is conservative, because heavy viscous damping
    keeps the overlaps below the elastic peak's: the same chain is within 3e-4 of the finer
    step up to 4 times the bound, 34 % off at 10 times and reaches infinite forces at 100 times.
    """
    from .timegrid import batched_program

    return float(np.max(np.asarray(batched_program(_damping_rate_one, np.ndim(setup.striker_velocity_m_s))(setup))))


def _damping_rate_one(setup):
    """`damping_rate_1_s` of one (unbatched) setup, 1/s (jnp)."""
    import jax.numpy as jnp

    from . import contact
    from .chain import build_model
    from .timegrid import peak_force_estimate_n

    model = build_model(setup)
    peak = peak_force_estimate_n(setup)
    law = (setup.contact_exponent, setup.exponent_reference_overlap_m) if setup.power_law else (None, None)

    def dashpot(kappa):
        overlap = contact.overlap_at_force(peak, jnp.where(kappa > 0, kappa, 1.0), *law)
        return jnp.where(kappa > 0, setup.dashpot_n_s_m + 1.5 * setup.eta_s * kappa * jnp.sqrt(overlap), 0.0)

    internal = jnp.where(model.is_spring, 0.0, dashpot(model.kappa))
    row = jnp.zeros_like(model.mass_kg).at[:-1].add(2.0 * internal).at[1:].add(2.0 * internal)
    row = row.at[-1].add(dashpot(model.wall_kappa))
    return jnp.max(row / model.mass_kg)


def check_step_stability(setup, dt_s: float, *, where: str = "") -> None:
    """Raise `ValueError` when the damping of `setup` (concrete, possibly batched) makes the
    velocity-Verlet step `dt_s` unstable (`damping_rate_1_s` times dt_s >= 1), naming the
    damping values, the largest stable step and, for an implausible value, its likely unit."""
    damping = (setup.eta_s, setup.dashpot_n_s_m)
    if not all(is_concrete(x) for x in damping) or not any(np.any(np.asarray(x) > 0) for x in damping):
        return
    rate = damping_rate_1_s(setup)
    if rate * dt_s < STABILITY_LIMIT:
        return
    values = []
    for name in ("eta_s", "dashpot_n_s_m"):
        array = np.asarray(getattr(setup, name), dtype=float).ravel()
        if np.any(array > 0):
            value = float(np.max(array))
            hint = unit_hint(name, value)
            values.append(f"{name} = {value:g} {RULES[name].unit}" + (f" ({hint})" if hint else ""))
    raise ValueError(
        f"{where}{', '.join(values) or 'the damping'} is beyond the stability of the time step: damping rate x dt_s = "
        f"{rate * dt_s:.3g} (stable below {STABILITY_LIMIT:g}); use dt_s < {STABILITY_LIMIT / rate:.3g} s "
        "(--dt) or less damping."
    )


# -- size of a run -------------------------------------------------------------------------

# Steps x bodies x runs above which a run is refused without confirmation (the paper's
# 21-bead chain over 2.5 ms is 1.3e5; a thousand such runs 1.3e8).
MAX_BODY_STEPS = 1e10


def available_memory_bytes() -> int | None:
    """Memory this machine can give a new computation now, bytes (Linux `MemAvailable`, else
    the free physical pages), or None where it cannot be read."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


class RunSize(NamedTuple):
    """What a run needs: `memory_bytes` (recorded samples of every channel in float64, three
    copies while assembled, the state of the step, and a result table) and `body_steps`
    (steps x bodies x runs)."""

    memory_bytes: float
    body_steps: float


def estimate_run_size(*, n_runs_in_memory: int, n_runs: int, n_bodies: int, n_channels: int, n_samples: int,
                      n_steps: int, n_table_values: int = 0) -> RunSize:
    """The `RunSize` of `n_runs` runs of `n_steps` steps, `n_runs_in_memory` of them at once,
    each recording `n_samples` samples of `n_channels` channels on a chain of `n_bodies`,
    and a result table of `n_table_values` numbers (three copies while it is assembled)."""
    samples = 3.0 * 8.0 * n_runs_in_memory * n_channels * n_samples
    state = 8.0 * n_runs_in_memory * n_bodies * 24
    table = 3.0 * 8.0 * n_table_values
    return RunSize(samples + state + table, float(n_runs) * n_steps * n_bodies)


# What a command that simulates a setup of its options can change to make a run smaller.
_SMALLER_MEMORY = ("shorten --t-end, raise --sample-interval, record fewer --contacts or use fewer beads "
                   "(a sweep: a smaller --chunk-size)")
_SMALLER_STEPS = "shorten --t-end, use fewer beads or grid values"


def check_run_size(size: RunSize, *, confirm_option: str = "--yes", memory_bytes: int | None = None,
                   smaller: tuple[str, str] = (_SMALLER_MEMORY, _SMALLER_STEPS), what: str = "this run") -> None:
    """Raise `ValueError` (one line naming the option that changes it, or `confirm_option`)
    when `size` needs more memory than is available or more than `MAX_BODY_STEPS`.
    `smaller`: what the command's user can change to need less memory, and fewer steps;
    `what`: the work the message speaks of."""
    available = available_memory_bytes() if memory_bytes is None else memory_bytes
    if available is not None and size.memory_bytes > available:
        raise ValueError(
            f"{what} needs about {size.memory_bytes / 2**30:.3g} GiB for its recorded samples, more than the "
            f"{available / 2**30:.3g} GiB available: {smaller[0]}, or add {confirm_option}."
        )
    if size.body_steps > MAX_BODY_STEPS:
        raise ValueError(
            f"{what} takes {size.body_steps:.3g} bead-steps (steps x beads x runs), above the limit of "
            f"{MAX_BODY_STEPS:.0e}: {smaller[1]}, or add {confirm_option} to run it anyway."
        )


def check_simulation_size(setup, options: dict) -> None:
    """`check_run_size` of one `simulate(setup, record_all=True, **options)` run (`options`:
    `t_end_s`, `sample_interval_s`, `dt_s`, as `cli.setup_options.run_options` gives them):
    every contact force and energy, position and velocity recorded."""
    from .timegrid import choose_time_grid

    grid = choose_time_grid(setup, t_end_s=options["t_end_s"], sample_interval_s=options["sample_interval_s"],
                            dt_s=options.get("dt_s"))
    n_bodies = setup.n_beads + 1 + len(setup.sensor_beads)
    check_run_size(estimate_run_size(n_runs_in_memory=1, n_runs=1, n_bodies=n_bodies, n_channels=4 * n_bodies + 2,
                                     n_samples=grid.n_samples, n_steps=grid.n_steps))


def check_batch_size(setup, *, n_runs: int, n_runs_in_memory: int, n_channels: int, t_end_s: float,
                     sample_interval_s: float, dt_s: float | None = None, confirm_option: str = "--yes") -> None:
    """`check_run_size` of `n_runs` runs of `setup`'s chain (`n_runs_in_memory` at once), each
    recording `n_channels` channels every `sample_interval_s` (s) up to `t_end_s` (s): the
    guard of the commands that run many shots (synth, sensitivity)."""
    from .timegrid import choose_time_grid

    grid = choose_time_grid(setup, t_end_s=t_end_s, sample_interval_s=sample_interval_s, dt_s=dt_s)
    n_bodies = setup.n_beads + 1 + len(setup.sensor_beads)
    check_run_size(estimate_run_size(n_runs_in_memory=max(1, min(n_runs, n_runs_in_memory)), n_runs=n_runs,
                                     n_bodies=n_bodies, n_channels=n_channels, n_samples=grid.n_samples,
                                     n_steps=grid.n_steps), confirm_option=confirm_option)


# -- yield -----------------------------------------------------------------------------------

def yield_velocity_m_s(setup) -> float:
    """Impact velocity at which the striker's Hertz collision with bead 1 reaches the yield
    force of contact 0 (`ChainSetup.contact_yield_force_n`), m/s (inf: no yield stress).

    From $\\tfrac12 m^* v^2 = \\tfrac25\\kappa\\delta^{5/2}$ at $\\kappa\\delta^{3/2} = F_Y$
    (`contact.velocity_for_peak_force`). Faster shots deform that contact plastically."""
    from . import contact

    striker, bead = float(setup.striker_mass_kg), float(setup.bead_mass_kg[0])
    yield_force = float(setup.contact_yield_force_n()[0])
    if not math.isfinite(yield_force):
        return math.inf
    kappa = float(setup.contact_kappa()[0])
    return float(contact.velocity_for_peak_force(striker * bead / (striker + bead), kappa, yield_force))


def yield_notice(setup, velocities_m_s, *, what: str = "shots") -> str | None:
    """One line naming the impact velocities beyond `yield_velocity_m_s` of an elastic setup
    and the option that models them, or None (none beyond, or `plasticity` on)."""
    if setup.plasticity:
        return None
    limit = yield_velocity_m_s(setup)
    over = sorted({float(v) for v in velocities_m_s if v > limit})
    if not over:
        return None
    return (
        f"{what} at {', '.join(f'{v:g}' for v in over)} m/s exceed the yield force of contact 0 (striker on bead 1: "
        f"{float(setup.contact_yield_force_n()[0]):.4g} N, reached above {limit:.3g} m/s): that contact deforms "
        "plastically, which the elastic model does not describe; add --plasticity thornton (or jackson_green) to "
        "model it, or keep the velocities below the limit."
    )
