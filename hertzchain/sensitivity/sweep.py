"""`sensitivity_sweep`: sensitivities over the outer product of swept parameter values,
vmapped in chunks, and the batching that global sensitivity shares with it."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..chain import ChainSetup
from ..parameters import (
    PARAMETERS,
    key_values,
    public_name,
    public_names,
    resolve_name,
    with_keys,
)
from ..progress import Progress
from ..timegrid import DEFAULT_STEPS_PER_CONTACT, TimeGrid, choose_time_grid
from .jacobian import jacobian_fn, n_values, observable_function, resolve_mode
from .local import check_keys, prepare
from .observables import Observable, invalid_reason
from .result import SensitivityResult, build_result


def check_axes(setup: ChainSetup, axes: Mapping[str, Sequence[float]], *,
               where: str = "sweep") -> dict[str, np.ndarray]:
    """Swept parameter (either spelling: a previous name warns) -> finite values (SI), keyed
    by registry key and checked as `check_keys` does; `where`: the argument `axes` was given
    as, named in the messages."""
    if not axes:
        raise ValueError(f"{where}: give at least one parameter to sweep, e.g. "
                         "{'striker_velocity_m_s': [0.1, 0.3], 'wall_youngs_pa': [5e9, 2.03e11]}.")
    out = {}
    for name, values in axes.items():
        try:
            key = resolve_name(name, where=where)
        except ValueError:
            key = None
        if key is None or PARAMETERS[key].per_bead:
            raise ValueError(
                f"{where}: cannot sweep {name!r}; sweepable parameters: {', '.join(public_names(per_bead=False))}."
            )
        array = np.asarray(values, dtype=float).ravel()
        if array.size == 0 or not np.all(np.isfinite(array)):
            raise ValueError(f"{where}: {public_name(key)} needs finite values, got {list(values)}.")
        if key in out:
            raise ValueError(f"{where}: {public_name(key)} is swept twice.")
        out[key] = array
    check_keys(setup, tuple(out))
    return out


def grid_for_batch(setup: ChainSetup, points: dict[str, jax.Array], **run) -> TimeGrid:
    """One time grid fine enough for `setup` at every point (registry key -> (n,) values)."""
    batched = jax.vmap(lambda v: with_keys(setup, v))(points)
    return choose_time_grid(batched, **run)


@eqx.filter_jit
def _jacobian_batch(batch, setup, params, observables, grid, mode):
    """`jacobian_at` vmapped over setups that differ in the parameters of `batch` (name ->
    (n,) values); also returns the parameter values of every setup."""
    fn = observable_function(setup, params, observables, grid)
    jac_fn = jacobian_fn(fn, mode)

    def one(point):
        base = with_keys(setup, point)
        values = key_values(base, params)
        return jac_fn(values, base) + (values,)

    return jax.vmap(one)(batch)


def jacobians_at_points(
    setup: ChainSetup,
    params: tuple[str, ...],
    observables: tuple[Observable, ...],
    points: dict[str, jax.Array],
    grid: TimeGrid,
    mode: str,
    *,
    chunk_size: int,
    label: str,
    progress: bool,
):
    """(observables, valid, jacobian, parameter values) at every point (name -> (n,) values),
    as NumPy arrays with a leading axis of n: vmapped in equal chunks (the last one padded
    with its last point), reporting progress under `label`."""
    size = int(next(iter(points.values())).shape[0])
    chunk = max(1, min(chunk_size, size))
    meter = Progress(size, label) if progress else None
    pieces = []
    for start in range(0, size, chunk):
        stop = min(start + chunk, size)
        idx = np.arange(start, start + chunk).clip(max=stop - 1)  # pad with the last point
        part = _jacobian_batch({k: v[idx] for k, v in points.items()}, setup, params, observables,
                               grid, mode)
        part = jax.tree_util.tree_map(lambda x, n=stop - start: np.asarray(x)[:n], part)
        pieces.append(part)
        if meter:
            meter.advance(stop - start)
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *pieces)


def undefined_messages(
    observables: Sequence[Observable], valid: dict, t_end_s: float, nowhere: str,
    describe: Callable[[np.ndarray], str],
) -> dict[str, str]:
    """Observable -> where and why it is undefined, for those undefined somewhere; raises
    `ValueError` (with the `nowhere` note) for one that is undefined at every point.
    `describe(ok)` names the points (e.g. "grid points (first: ...)")."""
    messages = {}
    for obs in observables:
        ok = np.asarray(valid[obs.name])
        if not ok.any():
            raise ValueError(invalid_reason(obs, t_end_s) + f" ({nowhere})")
        if not ok.all():
            messages[obs.name] = (
                f"undefined at {int((~ok).sum())} of {ok.size} {describe(ok)}: "
                + invalid_reason(obs, t_end_s)
            )
    return messages


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
    their outer product, e.g. `{"striker_velocity_m_s": [...], "wall_youngs_pa": [...]}`), and
    `chunk_size` setups per vmapped call. One time step, fine enough for every grid point,
    is used for all. Observables must be scalars (no `trace_*`).

    **Returns:** `SensitivityResult` with `grid_axes` and leading grid axes on every array.
    Observables that do not exist at some grid points (a pulse that has not arrived) are
    NaN there, flagged in `valid` and explained in `messages`; an observable that exists
    nowhere on the grid raises `ValueError`.
    """
    params, parsed = prepare(setup, params, observables)
    if any(o.is_trace for o in parsed):
        raise ValueError("sweep: whole-trace observables (trace_*) are not swept; use scalar ones.")
    axes = check_axes(setup, sweep)
    mesh = np.meshgrid(*axes.values(), indexing="ij")
    points = {name: jnp.asarray(m.ravel()) for name, m in zip(axes, mesh)}
    grid = grid_for_batch(setup, points, t_end_s=t_end_s, sample_interval_s=sample_interval_s,
                          dt_s=dt_s, steps_per_contact=steps_per_contact)
    mode = resolve_mode(mode, n_values(key_values(setup, params)), len(parsed))
    out, valid, jac, pvals = jacobians_at_points(
        setup, params, parsed, points, grid, mode, chunk_size=chunk_size,
        label="sensitivity sweep (setups)", progress=progress,
    )
    shape = tuple(len(v) for v in axes.values())
    reshape = lambda x: np.asarray(x).reshape(shape + np.asarray(x).shape[1:])  # noqa: E731
    out, valid, jac, pvals = (jax.tree_util.tree_map(reshape, t) for t in (out, valid, jac, pvals))

    def first_undefined(ok):
        first = np.argwhere(~ok)[0]
        where = ", ".join(f"{public_name(a)} = {axes[a][i]:g}" for a, i in zip(axes, first))
        return f"grid points (first: {where})"

    messages = undefined_messages(parsed, valid, grid.t_end_s, "at every grid point",
                                  first_undefined)
    return build_result(params, parsed, pvals, out, valid, jac, axes, mode, grid, messages)
