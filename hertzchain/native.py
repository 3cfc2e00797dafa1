"""The fused C++ kernel of the batched fast path (`chain_kernel.cc`), through `jax.ffi`.

XLA compiles the JAX kernel of `batched` into a few loops per step, each a pass over the
whole batch's state; `chain_kernel.cc` advances a block of 64 chains (8 for the rest of
the batch) through all the steps of the run while their state stays in the cache, computing every contact's force
once per step (the loop structure of a hand-written kernel). It covers the setups of the
fast path without damping or friction (Hertz contacts, sensor springs, preload, walls and
free ends), with or without the books, on the CPU; everything else runs the JAX kernel,
which stays the reference: the two agree to round-off (`tests/test_native.py`).

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
            print(f"hertzchain: compiling the fused chain kernel into {path} (once; ~10 s)",
                  file=sys.stderr, flush=True)
            _build(path)
        library = ctypes.cdll.LoadLibrary(str(path))
        jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(library.HertzChainForward), platform="cpu")
    except (OSError, RuntimeError) as error:
        return str(error)
    return None


def available() -> bool:
    """Whether the kernel is built and registered (it builds it on the first call)."""
    return _load() is None


def unavailable_reason() -> str | None:
    """Why the kernel cannot be used, or None when it can."""
    return _load()


def supports(flags, devices) -> bool:
    """Whether the kernel covers a compiled kernel's physics (`batched.KernelFlags`) on
    these devices: no damping or friction, CPU devices only."""
    if flags.full_state:
        return False
    platforms = {d.platform for d in devices} if devices else {jax.default_backend()}
    return platforms == {"cpu"} and available()


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
