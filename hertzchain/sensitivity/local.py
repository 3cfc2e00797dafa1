"""`sensitivity`: exact derivatives and elasticities at one setup, and the checks of the
parameter and observable names that every sensitivity study shares."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..chain import ChainSetup
from ..parameters import PARAMETERS, key_values, public_name, public_names, resolve_name
from ..timegrid import DEFAULT_STEPS_PER_CONTACT, TimeGrid, choose_time_grid
from .jacobian import jacobian_at, n_values, resolve_mode
from .observables import OBSERVABLE_FORMS, Observable, invalid_reason, parse_observable
from .result import SensitivityResult, build_result


def check_params(setup: ChainSetup, params: Sequence[str]) -> tuple[str, ...]:
    """The registry keys of `params` (either spelling, `hertzchain.parameters.resolve_name`:
    a previous name warns), checked as `check_keys` does."""
    if not tuple(params):
        raise ValueError(f"params: give at least one parameter; valid: {', '.join(public_names())}.")
    return check_keys(setup, tuple(resolve_name(name, where="params") for name in params))


def check_keys(setup: ChainSetup, params: tuple[str, ...]) -> tuple[str, ...]:
    """`params` (registry keys), checked: distinct, finite in `setup`, and acting in it (a
    sensor, a wall, elastic-plastic contacts, a positive preload where needed)."""
    if len(set(params)) != len(params):
        raise ValueError(f"params: a parameter is listed twice: {tuple(map(public_name, params))}.")
    for name in params:
        shown = public_name(name)
        value = np.asarray(PARAMETERS[name].get(setup), dtype=float)
        if not np.all(np.isfinite(value)):
            raise ValueError(
                f"params: {shown} is {value.tolist()} in this setup; its sensitivity is not defined "
                "(an infinitely stiff wall does not respond to its modulus): give a finite value."
            )
        if name.startswith("sensor_") and not setup.sensor_beads:
            raise ValueError(f"params: {shown} needs an embedded sensor (sensor_beads is empty).")
        if name in ("yield_stress", "yield_force") and not setup.plasticity:
            raise ValueError(
                f"params: {shown} acts only on elastic-plastic contacts; build the setup with "
                "plasticity=True (the elastic model only checks the yield force)."
            )
        if name == "precompression" and not float(setup.precompression_n) > 0:
            raise ValueError(
                "params: the sensitivity to precompression_n is singular at zero preload (the "
                "static overlap grows as F^(2/3)); evaluate it at a positive precompression_n."
            )
        if name in ("wall_youngs", "wall_poisson") and setup.end != "wall":
            raise ValueError(f"params: {shown} needs a wall (this chain has a free end).")
    return params


def prepare(
    setup: ChainSetup, params: Sequence[str], observables: Sequence[str] | str
) -> tuple[tuple[str, ...], tuple[Observable, ...]]:
    """Checked parameter keys (`check_params`) and parsed observables (`ValueError` names
    what is wrong)."""
    params = check_params(setup, params)
    if isinstance(observables, str):
        observables = [observables]
    parsed = tuple(parse_observable(setup, name) for name in observables)
    if not parsed:
        raise ValueError("observables: give at least one observable; valid forms: "
                         + "; ".join(OBSERVABLE_FORMS) + ".")
    if len({o.name for o in parsed}) != len(parsed):
        raise ValueError(f"observables: an observable is listed twice: {list(observables)}.")
    return params, parsed


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
    - `params`: parameters of `PARAMETERS`, by public name (e.g. `("eta_s", "mu",
      "wall_youngs_pa")`; a previous name, `eta`, is read with a `ParameterNameWarning`).
    - `observables`: names (see `hertzchain.sensitivity`, e.g. `("wall_peak", "contact_6_peak")`).
    - `t_end_s`, `sample_interval_s`, `dt_s`, `steps_per_contact`: the run, as in `simulate`
      (or give a ready `grid`).
    - `mode`: "auto" (by the Jacobian's shape), "forward" or "reverse".

    **Returns:** `SensitivityResult`, its parameters named by their public names.

    **Raises:** `ValueError` for unknown names (the valid ones are listed), observables not
    in the chain, and observables that do not exist in the run (e.g. a pulse that never
    arrives within `t_end_s`).
    """
    params, parsed = prepare(setup, params, observables)
    if grid is None:
        grid = choose_time_grid(setup, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                                dt_s=dt_s, steps_per_contact=steps_per_contact)
    values0 = key_values(setup, params)
    n_out = sum(grid.n_samples if o.is_trace else 1 for o in parsed)
    mode = resolve_mode(mode, n_values(values0), n_out)
    out, valid, jac = jacobian_at(values0, setup, params, parsed, grid, mode)
    for obs in parsed:
        if not bool(valid[obs.name]):
            raise ValueError(invalid_reason(obs, grid.t_end_s))
    return build_result(params, parsed, values0, out, valid, jac, {}, mode, grid, {})
