"""The Jacobian of observables with respect to parameters, by forward or reverse mode.

The run's time grid is fixed before differentiating, so a derivative is that of the
simulator on that grid. Forward mode (`jax.jacfwd`) costs one tangent pass per parameter
value, reverse mode (`jax.jacrev`) one cotangent pass per observable value: `choose_mode`
takes the cheaper.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..chain import ChainSetup
from ..integrate import solve
from ..parameters import with_keys
from ..timegrid import TimeGrid
from .observables import Observable, evaluate_observables, recording_for


def n_values(tree) -> int:
    """The number of scalars in a pytree of arrays."""
    return sum(int(np.prod(jnp.shape(x))) for x in jax.tree_util.tree_leaves(tree))


def choose_mode(n_inputs: int, n_outputs: int) -> str:
    """'reverse' when the Jacobian has fewer rows (observable values) than columns
    (parameter values), else 'forward': each mode's cost grows with its own dimension."""
    return "reverse" if n_outputs < n_inputs else "forward"


def resolve_mode(mode: str, n_inputs: int, n_outputs: int) -> str:
    """`mode` checked, with "auto" replaced by `choose_mode`'s choice."""
    if mode == "auto":
        return choose_mode(n_inputs, n_outputs)
    if mode not in ("forward", "reverse"):
        raise ValueError(f"mode must be 'auto', 'forward' or 'reverse', got {mode!r}.")
    return mode


def observable_function(
    setup: ChainSetup, params: Sequence[str], observables: Sequence[Observable], grid: TimeGrid
):
    """The function `values -> (observables, valid)` for a fixed time grid (differentiable).

    `values` is a dict parameter -> value, keyed by registry key or public name (as
    `hertzchain.parameters.key_values` or `parameter_values` gives them; not resolved here,
    so a user's names are resolved before: `local.check_params`); the rest of `setup` is held
    fixed.
    """
    recording = recording_for(observables)

    def fn(values, base=setup):
        changed = with_keys(base, values)
        traces = solve(changed, grid, recording)
        return evaluate_observables(changed, traces, observables, grid.sample_interval_s)

    return fn


def jacobian_fn(fn, mode: str):
    """(values, base) -> (observables, valid, jacobian) of `fn` with the AD `mode`."""

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
    return jacobian_fn(fn, mode)(values, setup)
