"""The lock-in grid of a driven chain on a fused host kernel (`hertzchain/kernels/csrc/driven_kernel.cc`).

`lockin_grid` advances every (frequency, drive) run through all of its steps with
`kernel.step`, one `lax.scan` whose every step is a few passes of XLA's loops over the
whole batch; a fit's Jacobian adds a pass per direction. The fused kernel runs a block of 16
runs at a time through all of its steps in registers and L1, accumulates the lock-in's sums
as the window's samples are made, and carries forward-mode tangents through the same loop
(`jax.custom_jvp`): the grid and every direction of a Jacobian in one call. Under
`jax.vmap` (`jax.custom_batching.custom_vmap`) mapped tangents (a `jacfwd`'s basis) join
the kernel's direction axis and mapped inputs its batch of runs. Reverse mode is not
available on it (`kernel="jax"`).

Its arithmetic is the JAX kernel's, operation for operation, with the contact law of
`chain_laws.h` (which every kernel shares and `tests/test_batched.py` holds to
`hertzchain.contact`): the two agree to round-off (`tests/test_driven_fused.py`). It reads
a bead's velocity or displacement; a contact's force runs the JAX kernel. The library is
built on first use (its own, so that sweeps of impacts never wait for it) into the cache of
`hertzchain.native`.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .. import native
from . import drive as drives
from .lockin import step_reference

SOURCE = native.DRIVEN_SOURCE
TARGET = "hertzchain_driven_lockin"
TANGENT_TARGET = "hertzchain_driven_lockin_tangent"
# The quantities the kernel reads (a bead's row of the state).
QUANTITIES = ("velocity", "displacement")


@functools.cache
def _load() -> str | None:
    """Build (if needed), load and register the kernel: None on success, else why not (said
    once on stderr, with what runs instead, by `native._load_library`)."""
    return native.registry.load_failure(_library)


@functools.cache
def _library():
    """Build (if needed), load and register the kernel's library: its path."""
    return native._load_library(
        (), "the driven chains' fused lock-in kernel",
        ((TARGET, "HertzChainDrivenLockin"), (TANGENT_TARGET, "HertzChainDrivenLockinTangent")), source=SOURCE,
        instead="the JAX kernel runs instead, about 7.5 times slower; hertzchain.driven.fused.unavailable_reason() "
                "gives the whole message, HERTZCHAIN_NATIVE=0 chooses the JAX kernel without this notice")


def unavailable_reason() -> str | None:
    """Why the kernel cannot run here (no compiler, switched off, not a CPU), or None."""
    if jax.default_backend() != "cpu":
        return f"runs on the CPU only (JAX's default backend is {jax.default_backend()!r})"
    return _load()


def runs(quantity: str) -> bool:
    """Whether the fused kernel runs a grid reading `quantity`, here."""
    return quantity in QUANTITIES and unavailable_reason() is None


def lockin_sums(p, frequency_hz, amplitude_m, *, steps_per_period: int, ramp_periods: int, hold_periods: int,
                window_periods: int, harmonics: tuple[float, ...], bead: int, quantity: str):
    """The lock-in's complex amplitudes (n_harmonics, B) of B runs (`frequency_hz`,
    `amplitude_m`: (B,), Hz and m) of the chain `p` (`kernel.KernelParams`), read as
    `schedule.lockin_levels` reads one level: `bead`'s `quantity` over the last
    `window_periods` of `ramp_periods` + `hold_periods` periods."""
    n = steps_per_period
    steps = (ramp_periods + hold_periods) * n
    window = window_periods * n
    config = (steps, ramp_periods * n, n, window, tuple(harmonics), bead - 1, quantity == "displacement",
              p.eta_s is not None)
    frequency = jnp.asarray(frequency_hz, dtype=jnp.float64)
    # each run's step and angular frequency, as `schedule._levels` and `drive.harmonic_segment` have them
    dt = 1.0 / (frequency * n)
    omega = 2.0 * jnp.pi * frequency
    eta = jnp.zeros(()) if p.eta_s is None else p.eta_s
    arrays = (p.inv_mass_per_kg, p.damping_rate_per_s, p.kappa_n_m1p5, p.static_overlap_m,
              jnp.reshape(eta, (1, 1)), jnp.asarray(amplitude_m, dtype=jnp.float64)[None], dt[None], omega[None])
    sums = _call(config)(*arrays)
    native.note_use(_library())
    return (2.0 / window) * jax.lax.complex(sums[0], sums[1])


def _tables(config):
    """The drive's and the lock-in's tables (functions of the step alone): cos and sin of
    the phase (N,), the ramp's smooth step and its slope (R + 1,), the reference (2, H, window)."""
    steps, ramp_steps, n, window, harmonics, _, _, _ = config
    theta = (2.0 * np.pi / n) * np.arange(n).astype(np.float64)
    if ramp_steps > 0:
        with jax.ensure_compile_time_eval():  # concrete numbers, also while a caller's jit traces
            step = drives.smooth_step(jnp.asarray(np.arange(ramp_steps + 1) / ramp_steps))
        shape, slope = (np.asarray(t) for t in step)
    else:
        shape, slope = np.ones(1), np.zeros(1)
    reference = np.stack([step_reference(window, n, h, steps - window + 1) for h in harmonics])
    return np.cos(theta), np.sin(theta), shape, slope, np.stack([reference.real, reference.imag])


@functools.cache
def _call(config):
    """The kernel for one configuration as a function of its eight arrays (each (rows, 1 or
    B)), with its JVP and batching rules: returns the sums (2, H, B)."""
    steps, ramp_steps, _, _, harmonics, row, displacement, viscous = config
    tables = _tables(config)
    attrs = {"steps": np.int64(steps), "ramp_steps": np.int64(ramp_steps), "row": np.int64(row),
             "displacement": np.int64(displacement), "viscous": np.int64(viscous)}
    n_arrays = 8

    def batch_of(arrays):
        return max(a.shape[-1] for a in arrays)

    @jax.custom_batching.custom_vmap
    def sums(*arrays):
        shape = jax.ShapeDtypeStruct((2, len(harmonics), batch_of(arrays)), jnp.float64)
        return jax.ffi.ffi_call(TARGET, shape)(*arrays, *tables, **attrs)

    @sums.def_vmap
    def _(size, batched, *arrays):
        out = sums(*native._fold_chains(size, batched, arrays, width=batch_of(arrays)))
        return native._unfold_chains(size, out, axis=2), True

    @jax.custom_batching.custom_vmap
    def sums_and_tangents(*args):
        """(the arrays, their tangents (D or 1, rows, B)) -> the sums (2, H, B) and their
        tangents (D, 2, H, B)."""
        arrays, tangents = args[:n_arrays], args[n_arrays:]
        batch, directions = batch_of(arrays), max(t.shape[0] for t in tangents)
        shapes = (jax.ShapeDtypeStruct((2, len(harmonics), batch), jnp.float64),
                  jax.ShapeDtypeStruct((directions, 2, len(harmonics), batch), jnp.float64))
        return tuple(jax.ffi.ffi_call(TANGENT_TARGET, shapes)(*arrays, *tangents, *tables, **attrs))

    @sums_and_tangents.def_vmap
    def _(size, batched, *args):
        arrays, tangents = args[:n_arrays], args[n_arrays:]
        if any(batched[:n_arrays]):
            # mapped inputs (a batch of chains or fits): their runs join the batch axis
            batch = batch_of(arrays)
            folded = native._fold_chains(size, batched[:n_arrays], arrays, width=batch)
            folded_t = native._fold_chains(size, batched[n_arrays:], tangents, width=batch)
            value, tangent = sums_and_tangents(*folded, *folded_t)
            return (native._unfold_chains(size, value, axis=2), native._unfold_chains(size, tangent, axis=3)), (
                True, True)
        # mapped tangents only (a jacfwd's basis): their directions join the direction axis
        value, tangent = sums_and_tangents(*arrays, *native._fold_directions(size, batched[n_arrays:], tangents))
        return (value, tangent.reshape((size, tangent.shape[0] // size) + tangent.shape[1:])), (False, True)

    @jax.custom_jvp
    def forward(*arrays):
        return sums(*arrays)

    @forward.defjvp
    def forward_jvp(primals, tangents):
        batch = batch_of(primals)
        # one direction, every tangent at its array's rows and the full batch width (a
        # jacfwd's basis or a vmap adds the rest through the batching rule above)
        directions = tuple(jnp.broadcast_to(t, p.shape[:-1] + (batch,))[None] for p, t in zip(primals, tangents))
        _, tangent = sums_and_tangents(*primals, *directions)
        # the values of the forward run (the tangent run's own are the same numbers): values
        # that do not depend on the tangents, which `jax.linearize` needs however deep in a
        # `jit` it meets them; XLA merges the call with a caller's forward run of the same grid
        return sums(*primals), tangent[0]

    return forward

