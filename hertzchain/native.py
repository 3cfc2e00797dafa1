"""The fused C++ kernels of the batched fast path (`chain_kernel.cc`), through `jax.ffi`.

XLA compiles the JAX kernel of `batched` into a few loops per step, each a pass over the
whole batch's state; `chain_kernel.cc` advances a block of 64 chains (8 for the rest of
the batch, then one at a time) through all the steps of the run while their state stays in
the cache, computing every contact's force once per step (the loop structure of a
hand-written kernel). Two kernels, each specialised at compile time (C++ templates) for the
physics it runs, so that the conservative case pays nothing for the rest:

- the conservative one (`run`): Hertz contacts, sensor springs, preload, walls and free
  ends, with or without the books (running maxima, energies);
- the full one (`run_full`): the same plus Kuwabara-Kono damping (the total force clipped
  at 0) and track friction, the recorded forces only, and forward-mode tangents carried
  through the same loop (`jax.custom_jvp`: `jax.jvp`, `jax.jacfwd`, `jax.linearize`; all
  the directions of a Jacobian in one run).

Everything else (the books of a damped chain, GPUs, reverse mode) runs the JAX kernel,
which stays the reference: they agree to round-off, values and derivatives
(`tests/test_native.py`), and every kernel's laws are held to `contact`'s
(`tests/test_batched.py::test_every_kernel_applies_the_laws_of_contact`).

The kernel is compiled on first use with the system's C++ compiler against the XLA FFI
headers that `jax.ffi.include_dir()` gives, for this machine's instruction set, and kept
in a cache directory (`$HERTZCHAIN_CACHE`, else `$XDG_CACHE_HOME/hertzchain`, else
`~/.cache/hertzchain`) keyed by the source, JAX's version and the CPU. Without a compiler
(or with `HERTZCHAIN_NATIVE=0`), `available()` is False, says why in `unavailable_reason()`,
and `solve_batched` runs the JAX kernel.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import jax
import numpy as np

SOURCE = Path(__file__).with_name("chain_kernel.cc")
TARGET = "hertzchain_chain_forward"
FULL_TARGET = "hertzchain_chain_full_forward"
TANGENT_TARGET = "hertzchain_chain_full_tangent"
# IEEE arithmetic as the JAX kernel rounds it: no contraction into fused multiply-adds,
# no fast math; -fno-math-errno lets the square roots vectorise.
FLAGS = ("-O3", "-march=native", "-ffp-contract=off", "-fno-math-errno", "-std=c++17",
         "-shared", "-fPIC")


def _cache_dir() -> Path:
    root = os.environ.get("HERTZCHAIN_CACHE")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hertzchain"


def _cpu_key() -> str:
    """The CPU's model and instruction-set flags (the library is built for them)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
        lines = [line for line in text.splitlines() if line.startswith(("model name", "flags"))][:2]
    except OSError:
        lines = []
    return platform.machine() + "|" + "|".join(lines)


def _library_path() -> Path:
    digest = hashlib.sha256()
    for part in (SOURCE.read_bytes(), jax.__version__.encode(), " ".join(FLAGS).encode(), _cpu_key().encode()):
        digest.update(part)
    return _cache_dir() / f"chain_kernel-{digest.hexdigest()[:16]}.so"


def _build(path: Path) -> None:
    """Compile the kernel into `path`, written whole or not at all."""
    compiler = os.environ.get("CXX") or shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")
    if compiler is None:
        raise RuntimeError("no C++ compiler found (set CXX, or install g++)")
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as scratch:
        partial = Path(scratch) / path.name
        command = [compiler, *FLAGS, f"-I{jax.ffi.include_dir()}", str(SOURCE), "-o", str(partial)]
        proc = subprocess.run(command, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"compiling {SOURCE.name} failed:\n{proc.stderr[-2000:]}")
        os.replace(partial, path)


@functools.cache
def _load() -> str | None:
    """Build (if needed), load and register the kernel: None on success, else why not."""
    if os.environ.get("HERTZCHAIN_NATIVE", "1") == "0":
        return "switched off (HERTZCHAIN_NATIVE=0)"
    try:
        path = _library_path()
        if not path.exists():
            print(f"hertzchain: compiling the fused chain kernel into {path} (once; 30-60 s)",
                  file=sys.stderr, flush=True)
            _build(path)
        library = ctypes.cdll.LoadLibrary(str(path))
        for name, symbol in ((TARGET, library.HertzChainForward), (FULL_TARGET, library.HertzChainFullForward),
                             (TANGENT_TARGET, library.HertzChainFullTangent)):
            jax.ffi.register_ffi_target(name, jax.ffi.pycapsule(symbol), platform="cpu")
    except (OSError, RuntimeError) as error:
        return str(error)
    return None


def available() -> bool:
    """Whether the kernel is built and registered (it builds it on the first call)."""
    return _load() is None


def unavailable_reason() -> str | None:
    """Why the kernel cannot be used, or None when it can."""
    return _load()


def library_path() -> Path:
    """Where this machine's build of the kernel is (or will be) kept."""
    return _library_path()


def kernel_for(flags, devices) -> str | None:
    """Which C++ kernel runs a compiled kernel's physics (`batched.KernelFlags`) on these
    devices: "conservative" (no damping or friction, books or not), "full" (damping or
    friction, the recorded forces only: no books), or None (the JAX kernel: books with
    damping or friction, a device other than the CPU, no compiler)."""
    platforms = {d.platform for d in devices} if devices else {jax.default_backend()}
    if platforms != {"cpu"} or (flags.full_state and flags.ledger) or not available():
        return None
    return "full" if flags.full_state else "conservative"


def run(p: dict, state0, *, dt_s: float, steps_per_sample: int, n_samples: int,
        channels: tuple[int, ...], preload: bool, springs: bool, books: bool):
    """Advance the packed state `state0` (rows, B) of `batched._Layout` through
    `n_samples` samples of `steps_per_sample` steps of `dt_s` seconds: returns the final
    state (rows, B) and one (B, n_samples) force trace per channel, N."""
    reason = _load()
    if reason is not None:
        raise RuntimeError(f"the fused chain kernel is unavailable: {reason}")
    batch = state0.shape[-1]
    zeros = np.zeros((p["kappa"].shape[0], 1))
    args = (
        state0,
        p["inv_mass"],
        p["kappa"],
        p["overlap0"] if preload else zeros,
        p["spring"] if springs else zeros,
        p["external"] if preload else np.zeros((p["inv_mass"].shape[0], 1)),
        np.asarray(channels, dtype=np.int64),
    )
    shapes = (jax.ShapeDtypeStruct(state0.shape, state0.dtype),) + tuple(
        jax.ShapeDtypeStruct((batch, n_samples), state0.dtype) for _ in channels
    )
    call = jax.ffi.ffi_call(TARGET, shapes, vmap_method="sequential")
    state, *traces = call(
        *args,
        dt=np.float64(dt_s),
        steps_per_sample=np.int64(steps_per_sample),
        preload=np.int64(preload),
        springs=np.int64(springs),
        books=np.int64(books),
    )
    return tuple(traces), state


def run_full(p: dict, x, v, a, *, dt_s: float, steps_per_sample: int, n_samples: int,
             channels: tuple[int, ...], viscous: bool, friction: bool, preload: bool, springs: bool):
    """The full step (`batched._step` with velocities and accelerations apart: damping,
    friction) from displacements `x`, velocities `v` and accelerations `a` (bodies + 1, B)
    at the impact, through `n_samples` samples of `steps_per_sample` steps of `dt_s`
    seconds: one (B, n_samples) force trace per channel, N, recorded after every sample.

    Differentiable in forward mode (`jax.jvp`, `jax.jacfwd`, `jax.linearize`) in every array
    of `p` and in the initial state: the tangents are carried through the same loop
    (`chain_kernel.cc`), all the directions of a `jacfwd` in one run. Reverse mode is not
    available (use the JAX kernel, `kernel="jax"`)."""
    reason = _load()
    if reason is not None:
        raise RuntimeError(f"the fused chain kernel is unavailable: {reason}")
    width = lambda leaf: leaf.shape[-1]  # noqa: E731
    zeros = lambda leaf: jax.numpy.zeros_like(leaf)  # noqa: E731
    args = (
        jax.numpy.concatenate([x, v, a]),
        p["inv_mass"],
        p["kappa"],
        p["overlap0"] if preload else zeros(p["overlap0"]),
        p["spring"] if springs else zeros(p["spring"]),
        p["external"] if preload else zeros(p["external"]),
        jax.numpy.reshape(p["eta"], (1, width(p["eta"]))),
        jax.numpy.reshape(p["friction"], (1, width(p["friction"]))),
    )
    config = (float(dt_s), int(steps_per_sample), int(n_samples), tuple(int(c) for c in channels),
              bool(viscous), bool(friction), bool(preload or springs))
    return _full_call(config)(*args)


@functools.cache
def _full_call(config):
    """The full kernel for one configuration as a function of its arrays, with its JVP."""
    dt_s, steps_per_sample, n_samples, channels, viscous, friction, extras = config
    attrs = dict(dt=np.float64(dt_s), steps_per_sample=np.int64(steps_per_sample),
                 viscous=np.int64(viscous), friction=np.int64(friction), extras=np.int64(extras))
    index = np.asarray(channels, dtype=np.int64)

    def shapes(state0, leading=()):
        batch = state0.shape[-1]
        return tuple(jax.ShapeDtypeStruct(leading + (batch, n_samples), state0.dtype) for _ in channels)

    @jax.custom_jvp
    def forward(*args):
        call = jax.ffi.ffi_call(FULL_TARGET, shapes(args[0]), vmap_method="sequential")
        return tuple(call(*args, index, **attrs))

    @forward.defjvp
    def forward_jvp(primals, tangents):
        batch = primals[0].shape[-1]
        # every tangent at its primal's rows and the full batch width, one direction. Under
        # vmap (a jacfwd's basis, or a batch of fits whose primals are batched too) the kernel
        # runs once per batch element ("sequential"): the handler takes primals of one chain
        # layout, and batched primals with an expanded direction axis are not that layout.
        directions = tuple(
            jax.numpy.broadcast_to(t, primal.shape[:-1] + (batch,))[None] for primal, t in zip(primals, tangents)
        )
        call = jax.ffi.ffi_call(TANGENT_TARGET, shapes(primals[0], (1,)), vmap_method="sequential")
        out = call(*primals, *directions, index, **attrs)
        return forward(*primals), tuple(t[0] for t in out)

    return forward
