"""`global_sensitivity`: derivative-based global sensitivity measures, the mean squared
elasticities over a Latin-hypercube sample of a parameter box."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import jax.numpy as jnp
import numpy as np

from ..chain import ChainSetup
from ..io.atomic import json_ready
from ..parameters import key_values, public_name
from .jacobian import n_values, resolve_mode
from .local import prepare
from .result import SensitivityResult, build_result
from .sweep import check_axes, grid_for_batch, jacobians_at_points, undefined_messages


@dataclasses.dataclass(frozen=True)
class GlobalSensitivity:
    """Derivative-based global sensitivity measures over a sampled parameter box.

    **Fields** (parameters by their public names, `eta_s`): `box` (param -> (low, high),
    SI), `n_samples` (points sampled; `n_valid` per observable where it exists),
    `mean_squared_elasticity` and `mean_abs_elasticity` (observable -> param -> value:
    $E[(\\partial\\ln O/\\partial\\ln p)^2]$ and $E|\\cdot|$ over the box), `ranking`
    (observable -> params from most to least influential), `samples` (the underlying
    `SensitivityResult`, grid axis "sample").
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

    **Arguments:** `box`: parameter (public name; a previous one warns) -> (low, high) in SI
    (uniform sampling); `params`: the
    parameters to rank (default: those of the box); `n_samples` points, drawn with `seed`;
    run options as `sensitivity`.

    **Returns:** `GlobalSensitivity` (grid points where an observable does not exist are
    left out of its means and counted in `n_valid`).
    """
    from scipy.stats import qmc

    if not box:
        raise ValueError("box: give at least one parameter range, e.g. {'eta_s': (0, 3e-6)}.")
    for name, bounds in box.items():
        if len(bounds) != 2 or not float(bounds[0]) <= float(bounds[1]):
            raise ValueError(f"box: {name} needs (low, high) with low <= high, got {bounds}.")
    if n_samples < 2:
        raise ValueError(f"n_samples must be at least 2, got {n_samples}.")
    names = list(box)
    unit = qmc.LatinHypercube(d=len(names), seed=seed).random(n_samples)
    low = np.array([float(box[n][0]) for n in names])
    high = np.array([float(box[n][1]) for n in names])
    points = low + unit * (high - low)
    names = list(check_axes(setup, {n: points[:, i] for i, n in enumerate(names)}, where="box"))
    params, parsed = prepare(setup, tuple(map(public_name, names)) if params is None else tuple(params),
                             observables)
    if any(o.is_trace for o in parsed):
        raise ValueError("global sensitivity: whole-trace observables (trace_*) are not supported.")
    batch = {n: jnp.asarray(points[:, i]) for i, n in enumerate(names)}
    grid = grid_for_batch(setup, batch, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                          dt_s=dt_s)
    mode = resolve_mode("auto", n_values(key_values(setup, params)), len(parsed))
    out, valid, jac, pvals = jacobians_at_points(
        setup, params, parsed, batch, grid, mode, chunk_size=chunk_size,
        label="global sensitivity (samples)", progress=progress,
    )
    axes = {"sample": np.arange(n_samples, dtype=float)}
    messages = undefined_messages(parsed, valid, grid.t_end_s, "anywhere in the box",
                                  lambda ok: "samples")
    samples = build_result(params, parsed, pvals, out, valid, jac, axes, mode, grid, messages)
    msq, mabs, ranking, n_valid = {}, {}, {}, {}
    for obs in samples.observables:
        ok = samples.valid[obs]
        n_valid[obs] = int(ok.sum())
        msq[obs], mabs[obs] = {}, {}
        for p in samples.params:
            e = samples.elasticity[obs][p][ok]
            e = e.reshape(e.shape[0], -1)
            msq[obs][p] = json_ready(np.mean(np.sum(e**2, axis=1)))
            mabs[obs][p] = json_ready(np.mean(np.sqrt(np.sum(e**2, axis=1))))
        ranking[obs] = sorted(samples.params, key=lambda p: -(msq[obs][p] or 0.0))
    return GlobalSensitivity(
        box={public_name(k): (float(low[i]), float(high[i])) for i, k in enumerate(names)},
        n_samples=n_samples,
        n_valid=n_valid,
        mean_squared_elasticity=msq,
        mean_abs_elasticity=mabs,
        ranking=ranking,
        samples=samples,
    )
