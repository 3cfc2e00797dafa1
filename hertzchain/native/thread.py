"""The one-thread-per-chain kernels (`chain_kernel_thread.cu`): one library per chain
length (its loops unrolled, its state in registers), built on first use with nvcc for this
machine's GPU ("cuda") or with the C++ compiler for the host ("emulated")."""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shlex
import shutil
import subprocess
from pathlib import Path

import jax

from . import build, registry

THREAD_SOURCE = build.CSRC / "chain_kernel_thread.cu"

# IEEE division and square roots (nvcc's defaults) and no contraction into fused
# multiply-adds: the JAX kernel's arithmetic, as on the host.
NVCC_FLAGS = ("-O3", "-arch=native", "--fmad=false", "-std=c++17", "-shared", "-Xcompiler", "-fPIC")

# The host build checks numbers, not speed: optimised lightly, it compiles in a few seconds.
EMULATION_FLAGS = ("-O1", "-ffp-contract=off", "-fno-math-errno", "-std=c++17", "-shared", "-fPIC")

# Extra flags for the one-thread-per-chain build (nvcc, or the C++ compiler of the host
# emulation), space-separated in this variable, e.g. "-DHC_ALWAYS_ROOT" or
# "-DHC_MIN_BLOCKS_PER_SM=3": to measure a variant of the kernel (`benchmarks/gpu_variants.py`).
# They are part of the build's cache key.
THREAD_FLAGS_VARIABLE = "HERTZCHAIN_THREAD_FLAGS"
_THREAD_SYMBOLS = {"forward": "HertzChainThreadForward", "full": "HertzChainThreadFullForward",
                   "tangent": "HertzChainThreadFullTangent"}


def _nvcc() -> str | None:
    found = shutil.which("nvcc")
    if found is None:
        home = os.environ.get("CUDA_HOME") or os.environ.get("CUDA_PATH") or "/usr/local/cuda"
        candidate = Path(home) / "bin" / "nvcc"
        found = str(candidate) if candidate.exists() else None
    return found


def thread_unavailable_reason(backend: str) -> str | None:
    """Why the one-thread-per-chain kernel cannot be built for `backend` ("cuda" or
    "emulated"), or None when it can."""
    if registry.switched_off():
        return registry.SWITCHED_OFF
    if backend == "cuda":
        return None if _nvcc() else "no CUDA compiler (nvcc) found (set CUDA_HOME, or install the CUDA toolkit)"
    if backend == "emulated":
        return None if build._cxx() else "no C++ compiler found (set CXX, or install g++)"
    raise ValueError(f'backend must be "cuda" or "emulated", got {backend!r}')


def _thread_build_command(backend: str, rows: int, output: Path) -> list[str]:
    define = [f"-DHC_ROWS={rows}", f"-I{jax.ffi.include_dir()}", f"-I{build.SOURCE.parent}",
              *shlex.split(os.environ.get(THREAD_FLAGS_VARIABLE, ""))]
    if backend == "cuda":
        return [_nvcc(), *NVCC_FLAGS, *define, str(THREAD_SOURCE), "-o", str(output)]
    return [build._cxx(), "-x", "c++", "-DHC_HOST_EMULATION", *EMULATION_FLAGS, *define, str(THREAD_SOURCE), "-o", str(output)]


@functools.cache
def _thread_target(backend: str, rows: int, kind: str) -> str:
    """The registered FFI target of `kind` ("forward", "full", "tangent") of the thread
    kernel for chains of `rows` - 1 bodies (built and registered on first use)."""
    _thread_library(backend, rows)
    return f"hertzchain_thread_{backend}_r{rows}_{kind}"


@functools.cache
def _thread_library(backend: str, rows: int) -> Path:
    """Build (if needed), load and register the thread kernel of `backend` for chains of
    `rows` - 1 bodies: its path. A library that cannot be built or loaded (the compiler
    fails, or the library does not load) raises RuntimeError or OSError, said once a
    process on stderr with the first line of why and recorded (`kernel_record`'s
    "not_available"); later calls raise at once."""
    reason = thread_unavailable_reason(backend)
    if reason is not None:
        raise RuntimeError(f"the {backend} chain kernel is unavailable: {reason}")
    digest = hashlib.sha256()
    toolchain = subprocess.run([_nvcc(), "--version"], capture_output=True, text=True, check=False).stdout if backend == "cuda" else build._cpu_key()
    for part in (THREAD_SOURCE.read_bytes(), build.LAWS.read_bytes(), build.FFI_ARGS.read_bytes(), jax.__version__.encode(),
                 " ".join(_thread_build_command(backend, rows, Path("-"))).encode(), toolchain.encode()):
        digest.update(part)
    path = build._cache_dir() / f"chain_thread-{backend}-r{rows}-{digest.hexdigest()[:16]}.so"
    if path in registry._FAILED:
        raise RuntimeError(registry._FAILED[path])
    what = f"the {backend} chain kernel for {rows - 1} bodies"
    try:
        sha256 = build._ensure_built(
            path, what,
            lambda out: build._compile(lambda partial: _thread_build_command(backend, rows, partial), out, THREAD_SOURCE.name),
            note="once")
        library = ctypes.cdll.LoadLibrary(str(path))
    except (OSError, RuntimeError) as error:
        registry._FAILED[path] = str(error) or type(error).__name__
        registry._announce_failure(what, error, "those runs take the JAX kernel instead")
        raise
    registry._LOADED[path] = sha256
    platform_name = "CUDA" if backend == "cuda" else "cpu"
    for kind, symbol in _THREAD_SYMBOLS.items():
        jax.ffi.register_ffi_target(f"hertzchain_thread_{backend}_r{rows}_{kind}",
                                    jax.ffi.pycapsule(getattr(library, symbol)), platform=platform_name)
    return path


def _thread_library_loads(backend: str, rows: int) -> bool:
    """Whether the thread kernel of `backend` for chains of `rows` - 1 bodies is built and
    loads (`_thread_library`); where it cannot be, that was said once on stderr and those
    runs take the JAX kernel."""
    try:
        _thread_library(backend, rows)
    except (OSError, RuntimeError):
        return False
    return True
