"""The fused kernels as JAX functions: their FFI calls on each backend, the conservative
run (`run`), the full run with forward-mode tangents (`run_full`) and with the books
(`run_full_books`), and their `jax.vmap` rules (mapped chains join the kernel's batch,
mapped tangents its directions)."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import numpy as np
from jax.interpreters import partial_eval

from .. import laws
from ..batched_step import law_from_arrays
from . import host, registry, thread
from .libraries import CONTACT_LAWS, HOST_LIBRARIES, RATE_LAW_DEFINES, HostLibrary, host_library_for


def _require(backend: str) -> None:
    reason = host._load() if backend == "host" else thread.thread_unavailable_reason(backend)
    if reason is not None:
        raise RuntimeError(f"the fused chain kernel ({backend}) is unavailable: {reason}")


class _Ffi(NamedTuple):
    """One kernel call on one backend: its target, and the layout of its traces (host: (B,
    n_samples); thread kernels: (n_samples, B), so that neighbouring threads write
    neighbouring addresses, transposed here)."""

    backend: str
    rows: int
    n_samples: int

    def trace_shapes(self, state0, count: int, leading: tuple = ()) -> tuple:
        batch = state0.shape[-1]
        shape = (batch, self.n_samples) if self.backend == "host" else (self.n_samples, batch)
        return tuple(jax.ShapeDtypeStruct(leading + shape, state0.dtype) for _ in range(count))

    def call(self, kind: str, library: HostLibrary, shapes, args, index, attrs, beads=()) -> tuple:
        """The run of `kind` ("forward", "full", "tangent", "books": `libraries.SYMBOLS`) in
        `library` (`libraries.HOST_LIBRARIES`: on the host, the library built on first use
        that holds it; the thread kernels compile the main library's and the dashpot's runs
        into one), the full runs with compliant sensors in `beads`."""
        if self.backend == "host":
            path = host._load_host_library(library)
            registry.note_use(path)
            # the host's full kernels take the sensors' beads after the channels (empty without)
            extra = () if kind == "forward" else (np.asarray(beads, dtype=np.int64),)
            return tuple(jax.ffi.ffi_call(library.target(kind), shapes)(*args, index, *extra, **attrs))
        target = thread._thread_target(self.backend, int(self.rows), kind)
        registry.note_use(thread._thread_library(self.backend, int(self.rows)), self.backend)
        return tuple(jax.ffi.ffi_call(target, shapes)(*args, channels=index, **attrs))

    def traces(self, traces) -> tuple:
        if self.backend == "host":
            return tuple(traces)
        return tuple(jax.numpy.swapaxes(trace, -1, -2) for trace in traces)


def run(p: dict, state0, *, dt_s: float, steps_per_sample: int, n_samples: int,
        channels: tuple[int, ...], preload: bool, springs: bool, books: bool, backend: str = "host"):
    """Advance the packed state `state0` (rows, B) of `batched._Layout` through
    `n_samples` samples of `steps_per_sample` steps of `dt_s` seconds: returns the final
    state (rows, B) and one (B, n_samples) force trace per channel, N. Under `jax.vmap`
    the mapped chains join the kernel's batch: one run for all of them. `backend`: "host"
    (the vectorised C++ kernel), "cuda" (one thread per chain on a GPU) or "emulated" (the
    CUDA kernel's source run on the host, one thread after another: for tests)."""
    _require(backend)
    zeros = np.zeros((p["kappa"].shape[0], 1))
    args = (
        state0,
        p["inv_mass"],
        p["kappa"],
        p["overlap0"] if preload else zeros,
        p["spring"] if springs else zeros,
        p["external"] if preload else np.zeros((p["inv_mass"].shape[0], 1)),
    )
    config = (float(dt_s), int(steps_per_sample), int(n_samples), tuple(int(c) for c in channels),
              bool(preload), bool(springs), bool(books), backend)
    state, *traces = _conservative_call(config)(*args)
    return tuple(traces), state


@functools.cache
def _conservative_call(config):
    """The conservative kernel for one configuration as a function of its arrays."""
    dt_s, steps_per_sample, n_samples, channels, preload, springs, books, backend = config
    attrs = {"dt": np.float64(dt_s), "steps_per_sample": np.int64(steps_per_sample), "preload": np.int64(preload),
             "springs": np.int64(springs), "books": np.int64(books)}
    index = np.asarray(channels, dtype=np.int64)

    @jax.custom_batching.custom_vmap
    def call(*args):
        state0 = args[0]
        ffi = _Ffi(backend, args[1].shape[-2], n_samples)
        shapes = (jax.ShapeDtypeStruct(state0.shape, state0.dtype),) + ffi.trace_shapes(state0, len(channels))
        state, *traces = ffi.call("forward", HOST_LIBRARIES["chain"], shapes, args, index, attrs)
        return (state,) + ffi.traces(traces)

    @call.def_vmap
    def _(size, batched, *args):
        state, *traces = call(*_fold_chains(size, batched, args))
        out = (_unfold_chains(size, state, axis=1),) + tuple(_unfold_chains(size, leaf) for leaf in traces)
        return out, (True,) * len(out)

    return call


def _fold_chains(size: int, batched, args, width: int | None = None):
    """The arrays of `size` vmapped kernel runs as the arrays of one run of `size` x B
    chains: every array (..., rows, 1 or B), mapped ones with a leading axis of `size`,
    becomes (..., rows, size B), chain (l, b) at column l B + b; an unmapped one of width 1
    stays (..., rows, 1) (shared by every chain) unless `width` (B) is given: then every
    array is spread to size B chains (the tangents, which the kernel reads per chain)."""
    chains = args[0].shape[-1] if width is None else width

    def fold(leaf, mapped):
        if width is None and not mapped and leaf.shape[-1] == 1:
            return leaf
        if not mapped:
            leaf = jax.numpy.broadcast_to(leaf, (size,) + leaf.shape)
        leaf = jax.numpy.broadcast_to(leaf, leaf.shape[:-1] + (chains,))
        leaf = jax.numpy.moveaxis(leaf, 0, -2)  # (..., rows, size, B)
        return leaf.reshape(leaf.shape[:-2] + (size * chains,))

    return tuple(fold(leaf, mapped) for leaf, mapped in zip(args, batched))


def _unfold_chains(size: int, leaf, axis: int = 0):
    """A result of a folded run, its chains (size B) on `axis`, back to `size` results
    (size, ...) with B chains each."""
    chains = leaf.shape[axis]
    leaf = leaf.reshape(leaf.shape[:axis] + (size, chains // size) + leaf.shape[axis + 1:])
    return jax.numpy.moveaxis(leaf, axis, 0)


def _fold_directions(size: int, batched, tangents):
    """Tangents (D or 1, rows, B) of `size` vmapped directional derivatives (a `jacfwd`'s
    basis) as the tangents of one run of size x D directions: mapped ones (size, D or 1,
    rows, B) become (size D, rows, B); unmapped ones of one direction stay shared (1, rows, B)."""
    directions = max(leaf.shape[1] if mapped else leaf.shape[0] for leaf, mapped in zip(tangents, batched))

    def fold(leaf, mapped):
        if not mapped and leaf.shape[0] == 1:
            return leaf
        if not mapped:
            leaf = jax.numpy.broadcast_to(leaf, (size,) + leaf.shape)
        leaf = jax.numpy.broadcast_to(leaf, (size, directions) + leaf.shape[2:])
        return leaf.reshape((size * directions,) + leaf.shape[2:])

    return tuple(fold(leaf, mapped) for leaf, mapped in zip(tangents, batched))


def run_full(p: dict, x, v, a, *, dt_s: float, steps_per_sample: int, n_samples: int,
             channels: tuple[int, ...], viscous: bool, friction: bool, preload: bool, springs: bool,
             rate_law: str | None = None, law: str = "hertz", backend: str = "host",
             sensors: tuple[int, ...] = (), sensor_state=None):
    """The full step (`batched_step._step` with velocities and accelerations apart: damping,
    friction) from displacements `x`, velocities `v` and accelerations `a` (bodies + 1, B)
    at the impact, through `n_samples` samples of `steps_per_sample` steps of `dt_s`
    seconds: one (B, n_samples) force trace per channel, N, recorded after every sample.

    Differentiable in forward mode (`jax.jvp`, `jax.jacfwd`, `jax.linearize`) in every array
    of `p` and in the initial state: the tangents are carried through the same loop
    (`chain_kernel.cc`), the forces and all the directions of a `jacfwd` in one run. Under
    `jax.vmap` the mapped chains join the kernel's batch (one run for all of them, with or
    without tangents): a vmapped batch of fits, `jacfwd` of `vmap` and `vmap` of `jacfwd`
    are one kernel run each. Reverse mode is not available (use the JAX kernel,
    `kernel="jax"`). `rate_law`: the law of the contacts' rate slot beside Kuwabara-Kono
    damping (needs `viscous`; `batched.KernelFlags.rate_law`): "dashpot", a linear dashpot on
    every contact (`p["dashpot"]`, N s/m), its terms compiled into this call's kernel only;
    "velocity_squared", the setup's `laws.VelocitySquared` (`p["dissipation"]`, its
    coefficient N s^2/m^2; Hertz contacts on the host, no compliant sensors), in a library
    of its own; or None. `law`: the contacts'
    elastic law (`batched.KernelFlags.law`: "hertz", or "power_law" on `contact.power_law_force`,
    "thornton" or "jackson_green" on the elastic-plastic laws of `forces.elastic_parts`, from
    the arrays `batched` stores for them; host only, each in a library of its own;
    an elastic-plastic run starts from the largest overlaps so far at `x`). `backend` as for
    `run`. `sensors`: beads K with a compliant sensor (`hertzchain.compliant_sensor`, the
    step of `batched_step._step`; on the host, in a library of its own for each law), whose
    parameters `p` holds as `batched` stores them ("sensor_beta", "sensor_inv",
    "sensor_back", "sensor_front", (n_sensors, 1 or B) each, and "first_force"), and
    `sensor_state` their forces (N), rates (N/s) and drives (N) at the impact, (3 n_sensors, B)."""
    _require(backend)
    sensors = tuple(int(k) for k in sensors)
    if sensors and backend != "host":
        raise ValueError("run_full: compliant sensors run on the host kernel (backend 'host').")
    if sensors and (sensor_state is None or sensor_state.shape[0] != 3 * len(sensors)):
        raise ValueError("run_full: sensor_state must hold the sensors' forces, rates and drives, "
                         "(3 n_sensors, B).")
    _library(law, rate_law, sensors, backend, "run_full")
    state0 = jax.numpy.concatenate([x, v, a] + ([sensor_state] if sensors else []))
    args = _full_args(p, state0, preload, springs, rate_law, law, backend, sensors)
    config = (float(dt_s), int(steps_per_sample), int(n_samples), tuple(int(c) for c in channels),
              bool(viscous), bool(friction), bool(preload or springs), rate_law, law, backend, sensors)
    return _full_call(config)(*args)


def run_full_books(p: dict, state0, *, dt_s: float, steps_per_sample: int, n_samples: int,
                   channels: tuple[int, ...], viscous: bool, friction: bool, preload: bool, springs: bool,
                   rate_law: str | None = None, law: str = "hertz"):
    """`run_full` with the books, on the host: advances the packed state `state0` (rows, B)
    of `batched._Layout` for the full step with the books (x, v, a; for elastic-plastic
    contacts every contact's largest overlap so far; every contact's largest total force; with damping, the viscous force on every body; the energy dissipated by
    damping and friction so far) and returns (the (B, n_samples) force traces, one per
    channel, N; the final packed state). The books' sums over the bodies follow
    `batched_step._step`'s order; the run is not differentiable (sweeps; fits call `run_full`).
    `rate_law`, `law` as for `run_full`."""
    _require("host")
    _check_rates(rate_law, viscous, "run_full_books")
    library = _library(law, rate_law, (), "host", "run_full_books")
    args = _full_args(p, state0, preload, springs, rate_law, law, "host", ()) + (p["mass"],)
    attrs = {"dt": np.float64(dt_s), "steps_per_sample": np.int64(steps_per_sample), "viscous": np.int64(viscous),
             "friction": np.int64(friction), "extras": np.int64(preload or springs),
             "dashpot": np.int64(rate_law is not None)}
    call = _Ffi("host", p["inv_mass"].shape[-2], n_samples)
    shapes = (jax.ShapeDtypeStruct(state0.shape, state0.dtype),) + call.trace_shapes(state0, len(channels))
    index = np.asarray(channels, dtype=np.int64)
    state, *traces = call.call("books", library, shapes, args, index, attrs)
    return tuple(traces), state


def _check_rates(rate_law: str | None, viscous: bool, caller: str) -> None:
    """A ValueError from `caller` where the rate slot holds a law (`rate_law`) but the run
    computes no rates (`viscous` False)."""
    if rate_law is not None and not viscous:
        raise ValueError(f"{caller}: a rate-slot law ({rate_law}) needs viscous=True (the kernel's rates come "
                         "with the damping).")


def _library(law: str, rate: str | None, sensors, backend: str, caller: str) -> HostLibrary:
    """The host library of a full run on `law`'s contacts with the rate slot's law `rate`
    (`run_full`'s `rate_law`) and compliant `sensors`, once `backend` is checked to run it
    (the thread kernels: Hertz contacts, with or without a dashpot, no sensors); else a
    ValueError from `caller` naming the fix."""
    if law not in CONTACT_LAWS:
        raise ValueError(f"{caller}: law must be one of {CONTACT_LAWS}, got {law!r}.")
    if rate is not None and rate not in RATE_LAW_DEFINES:
        raise ValueError(f"{caller}: rate_law must be None or one of {tuple(RATE_LAW_DEFINES)}, got {rate!r}.")
    library = host_library_for(law, rate, bool(sensors))
    if library is None:
        raise ValueError(f"{caller}: no native library runs {law} contacts with {rate} in the rate slot"
                         f"{' and compliant sensors' if sensors else ''} (rate_law='velocity_squared' needs "
                         "law='hertz' and sensors=()); the JAX kernel runs that combination.")
    if backend != "host" and not library.runs_on_threads:
        raise ValueError(f"{caller}: {law} contacts{f' with {rate}' if rate else ''}"
                         f"{' and compliant sensors' if sensors else ''} run on the host kernel (backend 'host').")
    return library


def _rate_slot_coefficient(p: dict, rate_law: str | None):
    """The coefficient the rate slot's law `rate_law` takes: the dashpot's (`p["dashpot"]`,
    N s/m), or that of the one law of that native name among the kernel arrays' other
    dissipation laws (`p["dissipation"]`, `batched._chain_params`; its
    `rate_slot_coefficient`); None without one."""
    if rate_law is None or rate_law == "dashpot":
        return None if rate_law is None else p["dashpot"]
    found = [law for law in p.get("dissipation", ()) if laws.registry.native_name(law) == rate_law]
    if len(found) != 1:
        raise ValueError(f"rate_law={rate_law!r}: the kernel arrays hold {len(found)} such laws; the rate slot "
                         "carries exactly one.")
    return found[0].rate_slot_coefficient()


def _full_args(p: dict, state0, preload: bool, springs: bool, rate_law: str | None, law: str, backend: str,
               sensors: tuple[int, ...] = ()) -> tuple:
    """The full kernels' arrays: the state, then the eight parameter arrays (zeros for the
    physics a run does not have; the rate slot's coefficient `rate_law`'s: the dashpot's or
    the velocity-squared law's) and, for the host kernels, the law's
    (`_law_array`) and the compliant sensors' (`_sensor_array`)."""
    slot = _rate_slot_coefficient(p, rate_law)
    width = lambda leaf: leaf.shape[-1]
    zeros = lambda leaf: jax.numpy.zeros_like(leaf)
    return (
        state0,
        p["inv_mass"],
        p["kappa"],
        p["overlap0"] if preload else zeros(p["overlap0"]),
        p["spring"] if springs else zeros(p["spring"]),
        p["external"] if preload else zeros(p["external"]),
        jax.numpy.reshape(p["eta"], (1, width(p["eta"]))),
        jax.numpy.reshape(p["friction"], (1, width(p["friction"]))),
        # the rate slot's coefficient (the linear dashpot's, N s/m, or velocity-squared
        # dissipation's, N s^2/m^2), zeros without one
        jax.numpy.reshape(slot, (1, width(slot))) if slot is not None else jax.numpy.zeros((1, 1)),
    ) + ((_law_array(p, law), _sensor_array(p, sensors)) if backend == "host" else ())


def _sensor_array(p: dict, sensors: tuple[int, ...]):
    """The compliant sensors' parameters as the host kernels' (rows, 1 or B) array
    (`chain_kernel.cc`'s `SensorRows`): their mass fractions, 1/omega0^2 (s^2), back and
    front compliances (m/N), then the preload's force on the first bead (N); one row of zeros
    without sensors."""
    if not sensors:
        return jax.numpy.zeros((1, 1))
    rows = [p["sensor_beta"], p["sensor_inv"], p["sensor_back"], p["sensor_front"],
            jax.numpy.reshape(p["first_force"], (1, -1))]
    width = max(row.shape[-1] for row in rows)
    return jax.numpy.concatenate([jax.numpy.broadcast_to(row, (row.shape[0], width)) for row in rows])


def _law_array(p: dict, law: str):
    """The parameters of the contact law named `law` as the host kernels' (rows, 1 or B)
    array (`chain_kernel.cc`'s `LawRows`): the law's `native_rows` from the kernel arrays
    (`batched_step.law_from_arrays`), each a row or a row per contact; two rows of zeros for
    a law without parameters (Hertz's)."""
    contact_law, constants = law_from_arrays(p, law)
    rows = contact_law.native_rows(constants)
    if not rows:
        return jax.numpy.zeros((2, 1))
    rows = [jax.numpy.reshape(row, (-1, row.shape[-1]) if row.ndim > 1 else (1, -1)) for row in rows]
    width = max(row.shape[-1] for row in rows)
    return jax.numpy.concatenate([jax.numpy.broadcast_to(row, (row.shape[0], width)) for row in rows])


@functools.cache
def _full_call(config):
    """The full kernel for one configuration as a function of its arrays, with its JVP."""
    dt_s, steps_per_sample, n_samples, channels, viscous, friction, extras, rate_law, law, backend, sensors = config
    _check_rates(rate_law, viscous, "run_full")
    attrs = {"dt": np.float64(dt_s), "steps_per_sample": np.int64(steps_per_sample),
             "viscous": np.int64(viscous), "friction": np.int64(friction), "extras": np.int64(extras),
             "dashpot": np.int64(rate_law is not None)}
    index = np.asarray(channels, dtype=np.int64)
    # the state, the eight parameter arrays (host: and the law's and the sensors')
    n_args = 11 if backend == "host" else 9
    library = _library(law, rate_law, sensors, backend, "run_full")

    def ffi(args):
        return _Ffi(backend, args[1].shape[-2], n_samples)

    @jax.custom_batching.custom_vmap
    def traces(*args):
        call = ffi(args)
        shapes = call.trace_shapes(args[0], len(channels))
        return call.traces(call.call("full", library, shapes, args, index, attrs, sensors))

    @traces.def_vmap
    def _(size, batched, *args):
        out = traces(*_fold_chains(size, batched, args))
        return tuple(_unfold_chains(size, leaf) for leaf in out), (True,) * len(out)

    @jax.custom_batching.custom_vmap
    def traces_and_tangents(*args):
        """(the arrays, their tangents (D or 1, rows, B)) -> the traces (B, n), then their
        tangents (D, B, n)."""
        primals, tangents = args[:n_args], args[n_args:]
        directions = max(t.shape[0] for t in tangents)
        call = ffi(primals)
        n = len(channels)
        out_shapes = call.trace_shapes(primals[0], n) + call.trace_shapes(primals[0], n, (directions,))
        out = call.call("tangent", library, out_shapes, primals + tangents, index, attrs, sensors)
        return call.traces(out[:n]) + call.traces(out[n:])

    @traces_and_tangents.def_vmap
    def _(size, batched, *args):
        n = len(channels)
        primals, tangents = args[:n_args], args[n_args:]
        if any(batched[:n_args]):
            # mapped primals (a batch of fits, or of chains): their chains join the batch
            # axis; the tangents' direction axis stays where it is
            folded = _fold_chains(size, batched[:n_args], primals)
            folded_t = _fold_chains(size, batched[n_args:], tangents, width=primals[0].shape[-1])
            out = traces_and_tangents(*folded, *folded_t)
            return (tuple(_unfold_chains(size, leaf) for leaf in out[:n])
                    + tuple(_unfold_chains(size, leaf, axis=1) for leaf in out[n:])), (True,) * (2 * n)
        # mapped tangents only (a jacfwd's basis): their directions join the direction axis
        out = traces_and_tangents(*primals, *_fold_directions(size, batched[n_args:], tangents))
        unfolded = tuple(leaf.reshape((size, leaf.shape[0] // size) + leaf.shape[1:]) for leaf in out[n:])
        return tuple(out[:n]) + unfolded, (False,) * n + (True,) * n

    @jax.custom_jvp
    def forward(*args):
        return traces(*args)

    @forward.defjvp
    def forward_jvp(primals, tangents):
        batch = primals[0].shape[-1]
        # every tangent at its primal's rows and the full batch width, one direction (a
        # jacfwd's basis or a vmap adds the rest through `traces_and_tangents`' batching rule)
        directions = tuple(
            jax.numpy.broadcast_to(t, primal.shape[:-1] + (batch,))[None] for primal, t in zip(primals, tangents)
        )
        out = traces_and_tangents(*primals, *directions)
        primal = tuple(out[: len(channels)])
        if any(isinstance(t, partial_eval.JaxprTracer) for t in tangents):
            # `jax.linearize` needs forces that do not depend on the (unknown) tangents:
            # the forward run's; elsewhere the tangent run's own (the same numbers)
            primal = traces(*primals)
        return primal, tuple(t[0] for t in out[len(channels):])

    return forward
