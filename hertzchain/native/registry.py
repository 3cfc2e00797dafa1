"""What this process did with the kernels' libraries: those it loaded (with their
SHA-256), those that could not be built or loaded (with why, announced once on stderr),
and those whose kernels computed its results (`kernel_record`, for result files)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from . import build

# `unavailable_reason()` where `HERTZCHAIN_NATIVE=0` switched the kernel off
SWITCHED_OFF = "switched off (HERTZCHAIN_NATIVE=0)"



def switched_off() -> bool:
    """Whether `HERTZCHAIN_NATIVE=0` switched the kernels off (every run takes the JAX kernel)."""
    return os.environ.get("HERTZCHAIN_NATIVE", "1") == "0"


def load_failure(load) -> str | None:
    """Call `load` (build if needed, load and register a kernel's library): None on success,
    else why not: `SWITCHED_OFF` where the kernels are switched off (`load` is then not
    called), or the text of the `OSError` or `RuntimeError` it raised."""
    if switched_off():
        return SWITCHED_OFF
    try:
        load()
    except (OSError, RuntimeError) as error:
        return str(error)
    return None


# The libraries this process failed to build or load: path -> why (tried once a process).
_FAILED: dict[Path, str] = {}

# The libraries this process loaded: path -> its SHA-256 (verified against its build record).
_LOADED: dict[Path, str] = {}

# The libraries whose kernels computed this process's results: file name -> (backend, SHA-256).
_USED: dict[str, tuple[str, str]] = {}

# What runs where one of the libraries built on first use cannot be built.
JAX_INSTEAD = "those runs take the JAX kernel instead, several times slower; `hertzchain kernel --all` shows why in full"


def _announce_failure(what: str, error: BaseException | str, instead: str) -> None:
    """Say on stderr, in one line, that `what` cannot be used, the first line of why and what
    runs instead."""
    text = str(error).strip()
    first = text.splitlines()[0] if text else type(error).__name__
    print(f"hertzchain: {what} cannot be used ({first}); {instead}.", file=sys.stderr, flush=True)


def note_use(path: Path, backend: str = "host") -> None:
    """Record that the kernels of the loaded library `path` ran on `backend` ("host",
    "cuda", "emulated") in this process (`kernel_record`)."""
    _USED[path.name] = (backend, _LOADED[path])


def kernel_record() -> dict:
    """Which kernels computed this process's results so far, for result files:
    `{"name": ..., "libraries": {file: SHA-256}}`, the name "native-<instructions>" for the
    host's fused kernels (e.g. "native-avx512", "native-avx2"; the `-march` of
    `HERTZCHAIN_NATIVE_ARCH`), "native-cuda" for the GPU's, "native-emulated" for the GPU
    kernel run on the host, joined by "+" where several ran; `{"name": "jax"}` where none
    did (every result then came from the JAX kernel). Where a library could not be built or
    loaded, its runs took the JAX kernel: "+jax" ends the name, and "not_available" gives
    each such library's file and the first line of why."""
    arch = os.environ.get(build.ARCH_VARIABLE, "native").strip() or "native"
    names = {"host": f"native-{build._instruction_set(arch)}", "cuda": "native-cuda", "emulated": "native-emulated"}
    backends = sorted({backend for backend, _ in _USED.values()}, key=list(names).index)
    record = {"name": "+".join([names[backend] for backend in backends] + (["jax"] if _FAILED or not _USED else []))}
    if _USED:
        record["libraries"] = {name: digest for name, (_, digest) in sorted(_USED.items())}
    if _FAILED:
        record["not_available"] = {path.name: (why.strip().splitlines() or ["unknown"])[0]
                                   for path, why in sorted(_FAILED.items())}
    return record
