"""`SensitivityResult`: derivatives and elasticities of observables with respect to
parameters, at one setup or over a grid of setups, with their JSON and CSV forms.

Elasticities are $\\partial\\ln O/\\partial\\ln p = (p/O)\\,\\partial O/\\partial p$. For a
parameter whose value is 0 the elasticity is 0; for an observable whose value is 0 it is
undefined and reported as None (JSON null). For whole traces the "elasticity" is
$p\\,\\partial F(t)/\\partial p$ divided by the trace's largest |F| (a pointwise ratio
would divide by zero before the pulse arrives).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..io.atomic import json_ready
from ..parameters import PARAMETERS, public_name
from ..timegrid import TimeGrid


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

    - `params`, `observables`: names (parameters by their public names, `eta_s`,
      `wall_youngs_pa`: `hertzchain.parameters`); `units`: name -> SI unit.
    - `param_values`: name -> value, shape `grid_shape + param_shape`.
    - `values`: observable -> value, shape `grid_shape + obs_shape` (NaN where invalid).
    - `derivative`, `elasticity`: observable -> param -> array of shape
      `grid_shape + obs_shape + param_shape` (SI; NaN where the observable is invalid or the
      elasticity undefined).
    - `valid`: observable -> bool array of shape `grid_shape`; `messages`: why not, per
      invalid observable (first grid point where it fails).
    - `grid_axes`: swept parameter (public name) -> values (empty for one setup); `mode`: "forward" or
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


def _units(params, parsed) -> dict:
    units = {public_name(p): PARAMETERS[p].unit for p in params}
    units.update({o.name: o.unit for o in parsed})
    return units


def build_result(params, parsed, param_values, out, valid, jac, axes, mode, grid, messages):
    """The `SensitivityResult` of a Jacobian evaluation (`out`, `valid`, `jac` as
    `jacobian_at` returns them, keyed by the registry keys `params`, with leading grid axes
    `axes`, keyed by registry keys or public names); NumPy, NaN where invalid, every
    parameter named by its public name."""
    shown = {p: public_name(p) for p in params}
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
            derivative[obs.name][shown[p]] = d
            elasticity[obs.name][shown[p]] = _elasticity(d, values[obs.name], param_values[p], obs.is_trace)
    return SensitivityResult(
        params=tuple(shown.values()),
        observables=tuple(o.name for o in parsed),
        units=_units(params, parsed),
        param_values={shown[p]: np.asarray(param_values[p], dtype=float) for p in params},
        values=values,
        derivative=derivative,
        elasticity=elasticity,
        valid={o.name: np.asarray(valid[o.name], dtype=bool) for o in parsed},
        messages=messages,
        grid_axes={public_name(k): np.asarray(v, dtype=float) for k, v in axes.items()},
        mode=mode,
        time_grid=grid,
        time_s=grid.sample_interval_s * np.arange(1, grid.n_samples + 1),
        trace_observables=tuple(o.name for o in parsed if o.is_trace),
    )
