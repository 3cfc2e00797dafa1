"""The fused C++ kernels of the batched fast path (`chain_kernel.cc`), through `jax.ffi`.

XLA compiles the JAX kernel of `batched` into a few loops per step, each a pass over the
whole batch's state; `chain_kernel.cc` advances a block of 64 chains (8 for the rest of
the batch, then one at a time) through all the steps of the run while their state stays in
the cache, computing every contact's force once per step (the loop structure of a
hand-written kernel). Two kernels, each specialised at compile time (C++ templates) for the
physics it runs, so that the conservative case pays nothing for the rest:

- the conservative one (`run`): Hertz contacts, sensor springs, preload, walls and free
  ends, with or without the books (running maxima, energies);
- the full one (`run_full`): the same plus Kuwabara-Kono damping and a linear dashpot (the
  total force clipped at 0) and track friction, the recorded forces only, and forward-mode tangents carried
  through the same loop (`jax.custom_jvp`: `jax.jvp`, `jax.jacfwd`, `jax.linearize`; the
  forces and all the directions of a Jacobian in one run); `run_full_books`, the same
  forward run with the books (largest forces, viscous work, friction losses, final state:
  what sweeps read), not differentiable. Both also run power-law contacts
  (`contact.power_law_force`, its tangents in the exponent and reference overlap included)
  and elastic-plastic ones (`contact.thornton_contact`, `contact.jackson_green_contact`,
  every contact's largest overlap so far carried through the steps, tangents in the yield
  constants included), each law from a library of its own (with or without a dashpot),
  built on first use, as the dashpot's runs on Hertz contacts are.

A run's blocks of chains are spread over the CPU's cores (XLA's intra-op thread pool, the
first free thread taking the next block; the runs of a process together use at most one
thread per core, so a batch already split over host devices gets no more), with the same
numbers whichever thread runs a block.

Loading the host kernel on Linux also asks glibc's malloc to reuse freed result buffers
(`_keep_freed_buffers`): XLA allocates every run's traces afresh, and without it each run
faults them in again page by page.

Under `jax.vmap` (`jax.custom_batching.custom_vmap`) a mapped batch of inputs joins the
kernel's chain axis and mapped tangents its direction axis, so a batch of fits, `jacfwd`
of `vmap` and `vmap` of `jacfwd` are one kernel run each.

The full kernel runs compliant sensor beads as well (`hertzchain.compliant_sensor`, on every
law, forward and tangent runs, no books), from a library of their own per law built on first
use.

Everything else (laws other than Hertz's on a GPU, compliant sensors on a GPU, the books of
a damped chain on a GPU, reverse mode) runs the JAX kernel,
which stays the reference: they agree to round-off, values and derivatives
(`tests/test_native.py`), and every kernel's laws are held to `contact`'s
(`tests/test_batched.py::test_every_kernel_applies_the_laws_of_contact`).

The kernel is compiled on first use with the system's C++ compiler against the XLA FFI
headers that `jax.ffi.include_dir()` gives, for this machine's instruction set (or the one
`$HERTZCHAIN_NATIVE_ARCH` names), and kept
in a cache directory (`$HERTZCHAIN_CACHE`, else `$XDG_CACHE_HOME/hertzchain`, else
`~/.cache/hertzchain`) keyed by the source, JAX's version and the CPU, each library with
its build record beside it (`<library>.json`: its size and SHA-256, written once the library
is in place). A library is loaded only once it matches its record: one that does not
(truncated, emptied, changed, or without a record) is named on stderr and built again.
A library that cannot be built is announced once, with the first line of why, and the runs
it serves take the JAX kernel; `kernel_record()` names the kernels that computed this
process's results, for result files. Without a compiler
(or with `HERTZCHAIN_NATIVE=0`), `available()` is False, says why in `unavailable_reason()`,
and `solve_batched` runs the JAX kernel.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import functools
import hashlib
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np
from jax.interpreters import partial_eval

from . import contact

try:
    import fcntl
except ImportError:  # not a POSIX system: builds are not serialised between processes
    fcntl = None

CSRC = Path(__file__).parent / "kernels" / "csrc"  # the kernels' C++ and CUDA sources
SOURCE = CSRC / "chain_kernel.cc"
# The driven chains' lock-in kernel (`hertzchain.driven.fused`), built by `_load_library` too.
DRIVEN_SOURCE = CSRC / "driven_kernel.cc"
LAWS = CSRC / "chain_laws.h"  # the laws both kernels include
FFI_ARGS = CSRC / "chain_ffi.h"  # their handlers' argument lists
TARGET = "hertzchain_chain_forward"
FULL_TARGET = "hertzchain_chain_full_forward"
TANGENT_TARGET = "hertzchain_chain_full_tangent"
BOOKS_TARGET = "hertzchain_chain_full_books"
# The full kernel with a linear dashpot: its terms compiled in for its runs alone (they cost
# every damped run ~17 % as a runtime term,
# `benchmarks/results/dashpot_kernel/history/dashpot_in_cpp_kernel_not_kept.md`),
# in a library of their own (`-D` DASHPOT_DEFINE) built on first use, so that the main
# library every run needs does not wait for them (36 s -> 50 s when built into it, 2 cores).
DASHPOT_DEFINE = "HC_DASHPOT_LIBRARY"
DASHPOT_FULL_TARGET = "hertzchain_chain_full_forward_dashpot"
DASHPOT_TANGENT_TARGET = "hertzchain_chain_full_tangent_dashpot"
DASHPOT_BOOKS_TARGET = "hertzchain_chain_full_books_dashpot"
# The full kernel with every contact on another law than Hertz's (`batched.KernelFlags.law`):
# the power law (`contact.power_law_force`), Thornton's and Jackson-Green's elastic-plastic
# laws (`contact.thornton_contact`, `contact.jackson_green_contact`), likewise each in a
# library of its own (`-D` its define), built on first use; its targets are
# "hertzchain_chain_full_{forward,tangent,books}_<law>", with or without a dashpot.
# The full kernel with compliant sensor beads (`hertzchain.compliant_sensor`; with or without
# a dashpot, forward and tangent runs, no books): likewise in a library of its own, built on
# first use (the diagnosis's sensor refits), on Hertz contacts and, with a law's define
# (`LAW_DEFINES`), on that law ("hertzchain_chain_full_{forward,tangent}_<law>_sensors").
SENSOR_DEFINE = "HC_SENSOR_LIBRARY"
SENSOR_FULL_TARGET = "hertzchain_chain_full_forward_sensors"
SENSOR_TANGENT_TARGET = "hertzchain_chain_full_tangent_sensors"
LAW_DEFINES = {"power_law": "HC_POWER_LIBRARY", "thornton": "HC_THORNTON_LIBRARY",
               "jackson_green": "HC_JACKSON_GREEN_LIBRARY"}
CONTACT_LAWS = ("hertz",) + tuple(LAW_DEFINES)
# IEEE arithmetic as the JAX kernel rounds it: no contraction into fused multiply-adds
# other than the source's own `std::fma`, no fast math; -fno-math-errno lets the square
# roots vectorise; -pthread for the threads the blocks of chains run on.
FLAGS = ("-O3", "-ffp-contract=off", "-fno-math-errno", "-std=c++17", "-pthread", "-shared", "-fPIC")
# The instruction set the kernel is built for: this CPU's ("native"), or the name of an
# older one in `HERTZCHAIN_NATIVE_ARCH` (e.g. "haswell": AVX2 and FMA, no AVX-512; GCC's
# `-march` names) to measure that code path on a newer machine.
ARCH_VARIABLE = "HERTZCHAIN_NATIVE_ARCH"
# For instruction sets without masked vector operations (AVX2 and older; AVX-512 has them).
# There GCC keeps a branch around arithmetic that could raise a floating-point exception
# under a condition (the slopes of the friction kick and of the clipped force in the
# tangent run) and leaves those loops scalar; -fno-trapping-math lets it compute both
# sides and select. The IEEE results are the same (exceptions are never read here). The
# AVX2 build's fit iteration went from 59.1 to 34.1 ms (`benchmarks/results/run/
# quick_avx2/history/epyc-avx512-as-avx2-2cores-quick-malloc/` and `...-quick-trapping/`); the AVX-512 build
# ran its tangents a few per cent slower with it, so it keeps the default.
UNMASKED_FLAGS = ("-fno-trapping-math",)


def _flags() -> tuple[str, ...]:
    """The compiler flags of this build: FLAGS, `-march` (see ARCH_VARIABLE) and, for an
    instruction set without vector masks, UNMASKED_FLAGS."""
    arch = os.environ.get(ARCH_VARIABLE, "native").strip() or "native"
    if not all(c.isalnum() or c in "-_." for c in arch):
        raise RuntimeError(f"{ARCH_VARIABLE}={arch!r} is not a -march name (e.g. native, haswell, x86-64-v3)")
    return (f"-march={arch}",) + FLAGS + (() if _has_vector_masks(arch) else UNMASKED_FLAGS)


def _has_vector_masks(arch: str) -> bool:
    """Whether the C++ compiler targets AVX-512 (masked vector operations) for `-march=arch`
    (its predefined macros); True where there is no compiler (nothing is built then)."""
    macros = _compiler_macros(arch)
    return macros is None or "__AVX512F__" in macros


@functools.cache
def _compiler_macros(arch: str) -> str | None:
    """The C++ compiler's predefined macros for `-march=arch`, or None without a compiler."""
    compiler = _cxx()
    if compiler is None:
        return None
    return subprocess.run([compiler, f"-march={arch}", "-dM", "-E", "-x", "c++", os.devnull],
                          capture_output=True, text=True, check=False).stdout


def _cache_dir() -> Path:
    root = os.environ.get("HERTZCHAIN_CACHE")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hertzchain"


# A cached library's name: its source and variant (the stem, e.g. "chain_kernel-sensor",
# "chain_thread-emulated-r22"), then the digest of everything its build read.
_LIBRARY_NAME = re.compile(r"^(?P<stem>(?:chain_kernel|chain_thread|driven_kernel)[a-z0-9_-]*?)-[0-9a-f]{16}\.so$")
# A build's scratch folder (`_compile`, `_build`) left by a process that was killed: one
# this old is no build in progress.
_STALE_SCRATCH_S = 3600.0


def _current_host_libraries() -> set[Path]:
    """The host libraries this installation builds on this machine with these flags: the
    main one, those built on first use (`load_on_demand_libraries`) and the driven chains'."""
    defines = [(), (f"-D{DASHPOT_DEFINE}",), (f"-D{SENSOR_DEFINE}",)] + [
        (f"-D{define}",) + extra for define in LAW_DEFINES.values() for extra in ((), (f"-D{SENSOR_DEFINE}",))]
    return {_library_path(d) for d in defines} | {_library_path((), DRIVEN_SOURCE)}


def prune_cache(now: float | None = None) -> tuple[int, int]:
    """Delete from the library cache (`_cache_dir`) the libraries that a newer build of the
    same kind has superseded: of every stem (source, variant and, for the thread kernels,
    chain length) the newest library stays, and so does every host library this
    installation builds here (`_current_host_libraries`); the others go with their lock
    files and build records, and so do build folders and half-written build records left
    over for more than an hour. A
    library that another installation still uses is built again on its next use. Returns
    (files deleted, bytes freed)."""
    now = time.time() if now is None else now
    folder = _cache_dir()
    if not folder.is_dir():
        return 0, 0
    kinds: dict[str, list[Path]] = {}
    for path in folder.iterdir():
        match = _LIBRARY_NAME.match(path.name)
        if match and path.is_file():
            kinds.setdefault(match["stem"], []).append(path)
    kept = _current_host_libraries() | {max(paths, key=lambda path: path.stat().st_mtime) for paths in kinds.values()}
    doomed = [path for paths in kinds.values() for path in paths if path not in kept]
    doomed += [path.with_name(path.name + suffix) for path in doomed for suffix in (".lock", ".json")]
    # build records half-written by a process that was killed (`_write_record`)
    doomed += [path for path in folder.iterdir() if path.name.startswith(".") and path.name.endswith(".tmp")
               and path.is_file() and now - path.stat().st_mtime > _STALE_SCRATCH_S]
    scratch = [path for path in folder.iterdir()
               if path.is_dir() and path.name.startswith("tmp") and now - path.stat().st_mtime > _STALE_SCRATCH_S]
    deleted = freed = 0
    for path in doomed:
        if path.exists():
            freed += path.stat().st_size
            path.unlink()
            deleted += 1
    for path in scratch:
        files = [part for part in path.rglob("*") if part.is_file()]
        freed += sum(part.stat().st_size for part in files)
        deleted += len(files)
        shutil.rmtree(path)
    return deleted, freed


def _cpu_key() -> str:
    """The CPU's model and instruction-set flags (the library is built for them)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
        lines = [line for line in text.splitlines() if line.startswith(("model name", "flags"))][:2]
    except OSError:
        lines = []
    return platform.machine() + "|" + "|".join(lines)


def _library_path(defines: tuple[str, ...] = (), source: Path = SOURCE) -> Path:
    """Where the host library built from `source` with `defines` is kept, keyed by everything
    its build reads."""
    digest = hashlib.sha256()
    headers = sorted(source.parent.glob("*.h"))  # every header beside the source: any it may include
    for part in (source.read_bytes(), *(header.read_bytes() for header in headers),
                 jax.__version__.encode(), " ".join(_flags() + defines).encode(), _cpu_key().encode()):
        digest.update(part)
    variant = "".join("-" + d.removeprefix("-DHC_").removesuffix("_LIBRARY").lower() for d in defines)
    return _cache_dir() / f"{source.stem}{variant}-{digest.hexdigest()[:16]}.so"


def _cxx() -> str | None:
    return os.environ.get("CXX") or shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")


def _compile(command_for, path: Path, name: str) -> None:
    """Run the compiler command `command_for(partial_path)` and move its output to `path`:
    written whole or not at all."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as scratch:
        partial = Path(scratch) / path.name
        proc = subprocess.run(command_for(partial), capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise _compile_error(name, proc.stderr)
        os.replace(partial, path)


def _compile_error(name: str, stderr: str) -> RuntimeError:
    """The failure of compiling `name`: its first line names the compiler's first error (the
    first line that says "error" or "fatal", else its first line), then the end of what the
    compiler printed."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    first = next((line for line in lines if re.search(r"error|fatal", line, re.IGNORECASE)), lines[0] if lines else "")
    return RuntimeError(f"compiling {name} failed: {first}\n{stderr[-2000:]}")


def _record_path(path: Path) -> Path:
    """The build record of the library `path`: `<library>.json` beside it."""
    return path.with_name(path.name + ".json")


def _file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _write_record(path: Path) -> None:
    """Record the size (bytes) and SHA-256 of the library `path`, already in place, beside
    it: written to a temporary file and renamed, so that a reader finds the whole record or
    none."""
    record = {"library": path.name, "bytes": path.stat().st_size, "sha256": _file_digest(path)}
    partial = path.with_name(f".{path.name}.json.{os.getpid()}.tmp")
    partial.write_text(json.dumps(record))
    os.replace(partial, _record_path(path))


# `_check`'s answer for a library that is not in the cache (built without a word about it)
_MISSING = "is not built"


def _check(path: Path) -> tuple[str | None, str | None]:
    """Whether the cached library `path` may be loaded: (None, its SHA-256) where it is the
    file its build recorded (`_write_record`), same size and digest; else (what is wrong,
    None)."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        return _MISSING, None
    if size == 0:
        return "is empty", None
    try:
        record = json.loads(_record_path(path).read_text())
        recorded_size, recorded_digest = int(record["bytes"]), str(record["sha256"])
    except FileNotFoundError:
        return "has no build record", None
    except (OSError, ValueError, KeyError, TypeError):
        return "has an unreadable build record", None
    if size != recorded_size:
        return f"holds {size} bytes where its build wrote {recorded_size} (truncated or changed)", None
    digest = _file_digest(path)
    if digest != recorded_digest:
        return "is not the file its build wrote (its SHA-256 differs)", None
    return None, digest


# How long a library's cold build takes, said when one is compiled: on two idle cores the
# main library took 110 s and each of the others about 60 s; on a loaded machine many times
# that (`benchmarks/results/kernel_build/latest.json` stores the load with the times).
BUILD_TIME_NOTE = "once; 1-2 minutes on two idle cores"


def _ensure_built(path: Path, what: str, build, *, announce: bool = True, note: str | None = None) -> str:
    """Make the library `path` ready to load and return its SHA-256: where it is not in the
    cache, `build(path)` compiles it (said on stderr when `announce`, with `note` on how long
    it takes, by default `BUILD_TIME_NOTE`'s); where it is there but
    does not match its build record (`_check`: truncated, emptied, changed or without a
    record), that is said in one line on stderr, the file is removed and it is built again.
    Under the library's build lock (`_build_lock`): of processes that need it at once, one
    builds and the others use its library."""
    problem, digest = _check(path)
    if problem is None:
        return digest
    with _build_lock(path):
        problem, digest = _check(path)  # (another process may have built it meanwhile)
        if problem is None:
            return digest
        if problem != _MISSING:
            print(f"hertzchain: the cached library {path} {problem}; building it again", file=sys.stderr, flush=True)
            path.unlink(missing_ok=True)
            _record_path(path).unlink(missing_ok=True)
        if announce:
            note = note or (f"{BUILD_TIME_NOTE}; `hertzchain kernel` builds all the libraries a first fit or "
                            "diagnosis needs at once")
            print(f"hertzchain: compiling {what} into {path} ({note})", file=sys.stderr, flush=True)
        began = time.perf_counter()
        build(path)
        _write_record(path)
        if announce:
            print(f"hertzchain: {what} built in {time.perf_counter() - began:.0f} s", file=sys.stderr, flush=True)
        problem, digest = _check(path)
        if problem is not None:
            raise RuntimeError(f"the library just built, {path}, {problem}")
        return digest


# The parts of `chain_kernel.cc` (its `HC_PART` values) that are compiled at once, each by its
# own compiler process, and linked into one library: the forward runs, and the tangent runs
# with the books. On 2 cores the main library then builds in about half the time of one unit.
SOURCE_PARTS = (1, 2)


def _libraries(defines: tuple[str, ...]) -> tuple[str, ...]:
    """What a library built with `defines` links beyond the C++ runtime: the power-law
    library, on x86-64 Linux, glibc's vector maths (libmvec: its vectorised `pow` and `log`,
    declared in `chain_kernel.cc`)."""
    vector_maths = platform.machine() == "x86_64" and platform.libc_ver()[0] == "glibc"
    return ("-lmvec",) if vector_maths and f"-D{LAW_DEFINES['power_law']}" in defines else ()


def _build(path: Path, defines: tuple[str, ...] = (), source: Path = SOURCE) -> None:
    """Compile the host kernel `source` into `path` (`defines`: `-D` macros): `chain_kernel.cc`
    as its `SOURCE_PARTS` in parallel, then linked; other sources as one unit."""
    compiler = _cxx()
    if compiler is None:
        raise RuntimeError("no C++ compiler found (set CXX, or install g++)")
    command = [compiler, *_flags(), *defines, f"-I{jax.ffi.include_dir()}", str(source)]
    if source != SOURCE:
        _compile(lambda partial: [*command, "-o", str(partial)], path, source.name)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=path.parent) as scratch:
        objects = [Path(scratch) / f"part{part}.o" for part in SOURCE_PARTS]
        compiling = [subprocess.Popen([*command, f"-DHC_PART={part}", "-c", "-o", str(out)], text=True,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                     for part, out in zip(SOURCE_PARTS, objects)]
        failed = [proc.communicate()[1] for proc in compiling]
        failed = [err for proc, err in zip(compiling, failed) if proc.returncode != 0]
        if failed:
            raise _compile_error(source.name, failed[0])
        _compile(lambda partial: [compiler, *_flags(), *map(str, objects), "-o", str(partial), *_libraries(defines)],
                 path, source.name)


# glibc's malloc options (mallopt): the size from which a request is served by its own
# mmap (here the largest glibc accepts, 32 MiB), and the free memory at the top of a heap
# that it keeps rather than hands back to the system.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
REUSED_BUFFER_BYTES = 32 << 20
KEPT_FREE_BYTES = 512 << 20
MALLOC_VARIABLE = "HERTZCHAIN_MALLOC_TUNING"


def _keep_freed_buffers() -> bool:
    """Ask glibc's malloc to serve result buffers up to `REUSED_BUFFER_BYTES` from its heaps
    and to keep up to `KEPT_FREE_BYTES` of freed memory: True where it was done.

    XLA allocates every result of a run afresh (a sweep's traces: tens of MB per channel).
    By default glibc maps each such buffer anew and unmaps it when freed, and its own
    adaptive threshold settles only after some runs: every page of the traces is then
    faulted in and zeroed again at each run. Measured on the standard damped case (N = 21,
    B = 1024, 2500 steps, 2 cores; `benchmarks/results/allocation/`): about 15
    thousand page faults per run and 0.90-0.98e9 bead-steps/s, against 3 faults and
    1.27-1.32e9 once freed buffers are reused. Process-wide (malloc has no per-caller
    setting), the memory kept is at most `KEPT_FREE_BYTES`; `HERTZCHAIN_MALLOC_TUNING=0`
    leaves malloc as it is. Not reached: the extra heaps of glibc's per-thread arenas,
    unmapped whenever they are empty (`MALLOC_ARENA_MAX=1` in the environment gives every
    thread the main heap; `benchmarks/README.md`, "Reused result memory").
    """
    if os.environ.get(MALLOC_VARIABLE, "1") == "0" or platform.system() != "Linux":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, REUSED_BUFFER_BYTES)
                    and libc.mallopt(_M_TRIM_THRESHOLD, KEPT_FREE_BYTES))
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False


# `unavailable_reason()` where `HERTZCHAIN_NATIVE=0` switched the kernel off
SWITCHED_OFF = "switched off (HERTZCHAIN_NATIVE=0)"


@functools.cache
def _load() -> str | None:
    """Build (if needed), load and register the kernel (and tune malloc for its results,
    `_keep_freed_buffers`): None on success, else why not (announced once by `_load_library`)."""
    if os.environ.get("HERTZCHAIN_NATIVE", "1") == "0":
        return SWITCHED_OFF
    _keep_freed_buffers()
    try:
        _load_main()
    except (OSError, RuntimeError) as error:
        return str(error)
    return None


@functools.cache
def _load_main() -> Path:
    """Build (if needed), load and register the main library (`_load_library`): its path."""
    return _load_library((), "the fused C++ kernel",
                         ((TARGET, "HertzChainForward"), (FULL_TARGET, "HertzChainFullForward"),
                          (TANGENT_TARGET, "HertzChainFullTangent"), (BOOKS_TARGET, "HertzChainFullBooks")),
                         instead="the JAX kernel runs instead, several times slower. "
                                 "hertzchain.native.unavailable_reason() gives the whole message; "
                                 "HERTZCHAIN_NATIVE=0 chooses the JAX kernel without this notice")


@contextlib.contextmanager
def _build_lock(path: Path):
    """Hold an exclusive lock on `path`'s build (a lock file beside it), so that processes that
    need the same library at once (test workers, the processes of a distributed sweep) build
    it once, the others waiting for it; no lock where the platform has no `fcntl`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if fcntl is None:
        yield
        return
    with open(path.with_name(path.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


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


def _load_library(defines: tuple[str, ...], what: str, targets, source: Path = SOURCE, *,
                  instead: str = JAX_INSTEAD) -> Path:
    """Build (if needed, `_ensure_built`) the host kernel `source` with `defines`, load it
    once it matches its build record and register its handler symbols as FFI targets
    (`targets`: (target, symbol) pairs); returns its path. A library that cannot be built or
    loaded raises RuntimeError or OSError, said once a process on stderr with the first line
    of why and `instead` (what runs in its place); later calls raise at once."""
    path = _library_path(defines, source)
    if path in _FAILED:
        raise RuntimeError(_FAILED[path])
    if path not in _LOADED:
        try:
            digest = _ensure_built(path, what, lambda out: _build(out, defines, source))
            library = ctypes.cdll.LoadLibrary(str(path))
        except (OSError, RuntimeError) as error:
            _FAILED[path] = str(error) or type(error).__name__
            _announce_failure(what, error, instead)
            raise
        for name, symbol in targets:
            jax.ffi.register_ffi_target(name, jax.ffi.pycapsule(getattr(library, symbol)), platform="cpu")
        _LOADED[path] = digest
    return path


def note_use(path: Path, backend: str = "host") -> None:
    """Record that the kernels of the loaded library `path` ran on `backend` ("host",
    "cuda", "emulated") in this process (`kernel_record`)."""
    _USED[path.name] = (backend, _LOADED[path])


@functools.cache
def _load_dashpot() -> Path:
    """Build (if needed), load and register the dashpot's full kernels (`DASHPOT_DEFINE`)."""
    return _load_library((f"-D{DASHPOT_DEFINE}",), "the fused chain kernel's dashpot runs",
                         ((DASHPOT_FULL_TARGET, "HertzChainFullForward"), (DASHPOT_TANGENT_TARGET, "HertzChainFullTangent"),
                          (DASHPOT_BOOKS_TARGET, "HertzChainFullBooks")))


@functools.cache
def _load_sensors(law: str = "hertz") -> Path:
    """Build (if needed), load and register the compliant sensors' full kernels (`SENSOR_DEFINE`)
    on `law`'s contacts."""
    if law == "hertz":
        return _load_library((f"-D{SENSOR_DEFINE}",), "the fused chain kernel's compliant sensors",
                             ((SENSOR_FULL_TARGET, "HertzChainFullForward"),
                              (SENSOR_TANGENT_TARGET, "HertzChainFullTangent")))
    return _load_library((f"-D{LAW_DEFINES[law]}", f"-D{SENSOR_DEFINE}"),
                         f"the fused chain kernel's compliant sensors on {law}",
                         ((_law_target("full", law) + "_sensors", "HertzChainFullForward"),
                          (_law_target("tangent", law) + "_sensors", "HertzChainFullTangent")))


def library_table() -> dict[str, tuple[tuple[str, ...], Path]]:
    """Every host library, by name: its `-D` macros and source. "chain" is the main library
    every run needs; the others are built on their first use: the dashpot's (Hertz contacts
    with a dashpot), the compliant sensors', each other contact law's (`LAW_DEFINES`, with or
    without a dashpot) and its compliant sensors', and the driven chains' lock-in kernel
    ("driven", `hertzchain.driven.fused`)."""
    table = {"chain": ((), SOURCE), "dashpot": ((f"-D{DASHPOT_DEFINE}",), SOURCE),
             "compliant sensors": ((f"-D{SENSOR_DEFINE}",), SOURCE)}
    table |= {law: ((f"-D{define}",), SOURCE) for law, define in LAW_DEFINES.items()}
    table |= {f"{law} compliant sensors": ((f"-D{define}", f"-D{SENSOR_DEFINE}"), SOURCE)
              for law, define in LAW_DEFINES.items()}
    table["driven"] = ((), DRIVEN_SOURCE)
    return table


# The libraries a first fit or diagnosis of impact data builds (measured: a diagnosis of a
# small chain from an empty cache), and a driven fit's; `hertzchain kernel` builds these.
FIRST_USE_LIBRARIES = ("chain", "dashpot", "compliant sensors", "jackson_green", "power_law",
                       "jackson_green compliant sensors", "driven")


def _load_named(name: str) -> Path:
    """Load the library `name` (`library_table`), building it where needed: its path."""
    if name == "chain":
        return _load_main()
    if name == "dashpot":
        return _load_dashpot()
    if name == "driven":
        from .driven import fused  # (the driven chains' kernel registers its own targets)

        return fused._library()
    law, _, sensors = name.partition(" ")
    if sensors:
        return _load_sensors("hertz" if law == "compliant" else law)
    return _load_law(law)


def build_libraries(names, jobs: int | None = None):
    """Build the libraries `names` (`library_table` keys) where they are not in the cache
    and verified, several at once (one compiler process each, the main library's parts two),
    then load each. **Arguments:**

    - `names`: which libraries, in the order their builds start (the longest first is best).
    - `jobs`: how many builds run at once (default: the CPU cores this process may use).

    **Yields** (name, path, seconds, why) as each library is done, in the order they finish:
    `why` is None where it was built (or already there) and loaded, else the whole message of
    its failure; seconds from the start of its build (or check) to its end.
    """
    table = library_table()
    unknown = [name for name in names if name not in table]
    if unknown:
        raise ValueError(f"unknown kernel libraries {unknown}; known: {', '.join(table)}")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    began = time.perf_counter()

    def build(name):
        defines, source = table[name]
        path = None
        try:
            path = _library_path(defines, source)
            _ensure_built(path, name, lambda out: _build(out, defines, source), announce=False)
        except (OSError, RuntimeError) as error:
            return name, path, str(error) or type(error).__name__
        return name, path, None

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs or cores or 1)) as pool:
        for future in concurrent.futures.as_completed([pool.submit(build, name) for name in names]):
            name, path, why = future.result()
            if why is None:
                try:
                    _load_named(name)
                except (OSError, RuntimeError) as error:
                    why = str(error) or type(error).__name__
            yield name, path, time.perf_counter() - began, why


def _law_target(kind: str, law: str) -> str:
    """The FFI target of a full run (`kind`: "full", "tangent" or "books") on `law`'s library."""
    return f"hertzchain_chain_full_{'forward' if kind == 'full' else kind}_{law}"


@functools.cache
def _load_law(law: str) -> Path:
    """Build (if needed), load and register the full kernels of a law other than Hertz's
    (`LAW_DEFINES`)."""
    return _load_library((f"-D{LAW_DEFINES[law]}",), f"the fused chain kernel's {law} runs",
                         tuple((_law_target(kind, law), symbol) for kind, symbol in (
                             ("full", "HertzChainFullForward"), ("tangent", "HertzChainFullTangent"),
                             ("books", "HertzChainFullBooks"))))


def available() -> bool:
    """Whether the kernel is built and registered (it builds it on the first call)."""
    return _load() is None


def unavailable_reason() -> str | None:
    """Why the kernel cannot be used, or None when it can."""
    return _load()


def cache_dir() -> Path:
    """Where the built libraries are kept: `$HERTZCHAIN_CACHE`, else `hertzchain` in
    `$XDG_CACHE_HOME` or `~/.cache`."""
    return _cache_dir()


def library_path() -> Path:
    """Where this machine's build of the kernel is (or will be) kept."""
    return _library_path()


def _instruction_set(arch: str) -> str:
    """The widest vector instructions the C++ compiler targets for `-march=arch`: "avx512",
    "avx2", "sse2", or the machine's name (`platform.machine()`) elsewhere."""
    macros = _compiler_macros(arch) or ""
    for name, macro in (("avx512", "__AVX512F__"), ("avx2", "__AVX2__"), ("sse2", "__SSE2__")):
        if macro in macros:
            return name
    return platform.machine().lower() or "unknown"


def kernel_record() -> dict:
    """Which kernels computed this process's results so far, for result files:
    `{"name": ..., "libraries": {file: SHA-256}}`, the name "native-<instructions>" for the
    host's fused kernels (e.g. "native-avx512", "native-avx2"; the `-march` of
    `HERTZCHAIN_NATIVE_ARCH`), "native-cuda" for the GPU's, "native-emulated" for the GPU
    kernel run on the host, joined by "+" where several ran; `{"name": "jax"}` where none
    did (every result then came from the JAX kernel). Where a library could not be built or
    loaded, its runs took the JAX kernel: "+jax" ends the name, and "not_available" gives
    each such library's file and the first line of why."""
    arch = os.environ.get(ARCH_VARIABLE, "native").strip() or "native"
    names = {"host": f"native-{_instruction_set(arch)}", "cuda": "native-cuda", "emulated": "native-emulated"}
    backends = sorted({backend for backend, _ in _USED.values()}, key=list(names).index)
    record = {"name": "+".join([names[backend] for backend in backends] + (["jax"] if _FAILED or not _USED else []))}
    if _USED:
        record["libraries"] = {name: digest for name, (_, digest) in sorted(_USED.items())}
    if _FAILED:
        record["not_available"] = {path.name: (why.strip().splitlines() or ["unknown"])[0]
                                   for path, why in sorted(_FAILED.items())}
    return record


class FusedKernel(NamedTuple):
    """A fused kernel: its physics, "conservative" (no damping or friction, books or not) or
    "full" (damping, friction, forward-mode tangents, the recorded forces only), and where
    it runs, "host" (`chain_kernel.cc`), "cuda" (`chain_kernel_thread.cu` on a GPU) or
    "emulated" (the CUDA kernel's source on the host, one thread after another: tests)."""

    physics: str
    backend: str


def _host_library_loads(flags) -> bool:
    """Whether the host library that runs `flags`' physics (`batched.KernelFlags`) beyond the
    main library's (compliant sensors, another law, a dashpot) loads; where it cannot be
    built, that was said once on stderr and those runs take the JAX kernel."""
    try:
        if flags.sensors:
            _load_sensors(flags.law)
        elif flags.law != "hertz":
            _load_law(flags.law)
        elif flags.dashpot:
            _load_dashpot()
    except (OSError, RuntimeError):
        return False
    return True


def _platforms(devices) -> set[str]:
    """The platforms ("cpu", "gpu") of `devices`, or JAX's default one where none are given."""
    return {d.platform for d in devices} if devices else {jax.default_backend()}


def kernel_for(flags, devices, rows: int | None = None) -> FusedKernel | None:
    """Which fused kernel runs a compiled kernel's physics (`batched.KernelFlags`) on these
    devices, or None (the JAX kernel: laws other than Hertz's on a GPU, compliant sensors on
    a GPU or with the books, the books of damping or friction on a GPU, devices
    of another kind, no compiler, a library that cannot be built or loaded). `rows`: the
    kernel arrays' rows (bodies + 1); where given, the GPU's thread kernel for that chain
    length is built and loaded here, and one that cannot be (said once on stderr) gives None."""
    platforms = _platforms(devices)
    if flags.sensors:  # compliant sensors: the host's sensor libraries, no books
        if flags.ledger or platforms != {"cpu"} or not available() or not _host_library_loads(flags):
            return None
        return FusedKernel("full", "host")
    if flags.law != "hertz":  # the full kernel's library of the law (`LAW_DEFINES`), on the host
        if platforms != {"cpu"} or not available() or not _host_library_loads(flags):
            return None
        return FusedKernel("full", "host")
    physics = "full" if flags.full_state else "conservative"
    if platforms == {"cpu"} and available() and _host_library_loads(flags):
        return FusedKernel(physics, "host")
    if flags.full_state and flags.ledger:  # the thread kernels keep no books of the full step
        return None
    if platforms == {"gpu"} and thread_unavailable_reason("cuda") is None and (
            rows is None or _thread_library_loads("cuda", int(rows))):
        return FusedKernel(physics, "cuda")
    return None


# ---------------------------------------------------------------------------------------
# The one-thread-per-chain kernels (`chain_kernel_thread.cu`): one library per chain
# length (its loops unrolled, its state in registers), built on first use with nvcc for
# this machine's GPU ("cuda") or with the C++ compiler for the host ("emulated").

THREAD_SOURCE = CSRC / "chain_kernel_thread.cu"
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
_HOST_TARGETS = {"forward": TARGET, "full": FULL_TARGET, "tangent": TANGENT_TARGET, "books": BOOKS_TARGET,
                 "full_dashpot": DASHPOT_FULL_TARGET, "tangent_dashpot": DASHPOT_TANGENT_TARGET,
                 "books_dashpot": DASHPOT_BOOKS_TARGET, "full_sensors": SENSOR_FULL_TARGET,
                 "tangent_sensors": SENSOR_TANGENT_TARGET} | {
                     f"{kind}_{law}": _law_target(kind, law) for law in LAW_DEFINES for kind in ("full", "tangent", "books")} | {
                     f"{kind}_{law}_sensors": _law_target(kind, law) + "_sensors" for law in LAW_DEFINES
                     for kind in ("full", "tangent")}


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
    if os.environ.get("HERTZCHAIN_NATIVE", "1") == "0":
        return SWITCHED_OFF
    if backend == "cuda":
        return None if _nvcc() else "no CUDA compiler (nvcc) found (set CUDA_HOME, or install the CUDA toolkit)"
    if backend == "emulated":
        return None if _cxx() else "no C++ compiler found (set CXX, or install g++)"
    raise ValueError(f'backend must be "cuda" or "emulated", got {backend!r}')


def _thread_build_command(backend: str, rows: int, output: Path) -> list[str]:
    define = [f"-DHC_ROWS={rows}", f"-I{jax.ffi.include_dir()}", f"-I{SOURCE.parent}",
              *shlex.split(os.environ.get(THREAD_FLAGS_VARIABLE, ""))]
    if backend == "cuda":
        return [_nvcc(), *NVCC_FLAGS, *define, str(THREAD_SOURCE), "-o", str(output)]
    return [_cxx(), "-x", "c++", "-DHC_HOST_EMULATION", *EMULATION_FLAGS, *define, str(THREAD_SOURCE), "-o", str(output)]


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
    toolchain = subprocess.run([_nvcc(), "--version"], capture_output=True, text=True, check=False).stdout if backend == "cuda" else _cpu_key()
    for part in (THREAD_SOURCE.read_bytes(), LAWS.read_bytes(), FFI_ARGS.read_bytes(), jax.__version__.encode(),
                 " ".join(_thread_build_command(backend, rows, Path("-"))).encode(), toolchain.encode()):
        digest.update(part)
    path = _cache_dir() / f"chain_thread-{backend}-r{rows}-{digest.hexdigest()[:16]}.so"
    if path in _FAILED:
        raise RuntimeError(_FAILED[path])
    what = f"the {backend} chain kernel for {rows - 1} bodies"
    try:
        digest = _ensure_built(
            path, what,
            lambda out: _compile(lambda partial: _thread_build_command(backend, rows, partial), out, THREAD_SOURCE.name),
            note="once")
        library = ctypes.cdll.LoadLibrary(str(path))
    except (OSError, RuntimeError) as error:
        _FAILED[path] = str(error) or type(error).__name__
        _announce_failure(what, error, "those runs take the JAX kernel instead")
        raise
    _LOADED[path] = digest
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


def _require(backend: str) -> None:
    reason = _load() if backend == "host" else thread_unavailable_reason(backend)
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

    def call(self, kind: str, shapes, args, index, attrs, beads=()) -> tuple:
        """`kind`: "forward", "full", "tangent", "books", the last three with a dashpot
        ("_dashpot": its own host library; the thread kernels compile it into the same one) or
        on another law ("_<law>", a `LAW_DEFINES` key: its own host library), the first two
        also with compliant sensors ("_sensors", in `beads`: their own host library)."""
        if self.backend == "host":  # the library built on first use that holds the handler
            law = next((law for law in LAW_DEFINES if f"_{law}" in kind), "hertz")
            if kind.endswith("_sensors"):
                path = _load_sensors(law)
            elif kind.endswith("_dashpot"):
                path = _load_dashpot()
            elif law != "hertz":
                path = _load_law(law)
            else:
                path = _load_main()
            note_use(path)
            # the host's full kernels take the sensors' beads after the channels (empty without)
            extra = () if kind == "forward" else (np.asarray(beads, dtype=np.int64),)
            return tuple(jax.ffi.ffi_call(_HOST_TARGETS[kind], shapes)(*args, index, *extra, **attrs))
        target = _thread_target(self.backend, int(self.rows), kind.removesuffix("_dashpot"))
        note_use(_thread_library(self.backend, int(self.rows)), self.backend)
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
        state, *traces = ffi.call("forward", shapes, args, index, attrs)
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
             dashpot: bool = False, law: str = "hertz", backend: str = "host",
             sensors: tuple[int, ...] = (), sensor_state=None):
    """The full step (`batched._step` with velocities and accelerations apart: damping,
    friction) from displacements `x`, velocities `v` and accelerations `a` (bodies + 1, B)
    at the impact, through `n_samples` samples of `steps_per_sample` steps of `dt_s`
    seconds: one (B, n_samples) force trace per channel, N, recorded after every sample.

    Differentiable in forward mode (`jax.jvp`, `jax.jacfwd`, `jax.linearize`) in every array
    of `p` and in the initial state: the tangents are carried through the same loop
    (`chain_kernel.cc`), the forces and all the directions of a `jacfwd` in one run. Under
    `jax.vmap` the mapped chains join the kernel's batch (one run for all of them, with or
    without tangents): a vmapped batch of fits, `jacfwd` of `vmap` and `vmap` of `jacfwd`
    are one kernel run each. Reverse mode is not available (use the JAX kernel,
    `kernel="jax"`). `dashpot`: a linear dashpot on every contact (`p["dashpot"]`, N s/m;
    needs `viscous`), its terms compiled into this call's kernel only. `law`: the contacts'
    elastic law (`batched.KernelFlags.law`: "hertz", or "power_law" on `contact.power_law_force`,
    "thornton" or "jackson_green" on the elastic-plastic laws of `forces.elastic_parts`, from
    the arrays `batched` stores for them; host only, each in a library of its own;
    an elastic-plastic run starts from the largest overlaps so far at `x`). `backend` as for
    `run`. `sensors`: beads K with a compliant sensor (`hertzchain.compliant_sensor`, the
    step of `batched._step`; on the host, in a library of its own for each law), whose
    parameters `p` holds as `batched` stores them ("sensor_beta", "sensor_inv",
    "sensor_back", "sensor_front", (n_sensors, 1 or B) each, and "first_force"), and
    `sensor_state` their forces (N), rates (N/s) and drives (N) at the impact, (3 n_sensors, B)."""
    _require(backend)
    _check_law(law, backend, "run_full")
    sensors = tuple(int(k) for k in sensors)
    if sensors and backend != "host":
        raise ValueError("run_full: compliant sensors run on the host kernel (backend 'host').")
    if sensors and (sensor_state is None or sensor_state.shape[0] != 3 * len(sensors)):
        raise ValueError("run_full: sensor_state must hold the sensors' forces, rates and drives, "
                         "(3 n_sensors, B).")
    state0 = jax.numpy.concatenate([x, v, a] + ([sensor_state] if sensors else []))
    args = _full_args(p, state0, preload, springs, dashpot, law, backend, sensors)
    config = (float(dt_s), int(steps_per_sample), int(n_samples), tuple(int(c) for c in channels),
              bool(viscous), bool(friction), bool(preload or springs), bool(dashpot), law, backend, sensors)
    return _full_call(config)(*args)


def run_full_books(p: dict, state0, *, dt_s: float, steps_per_sample: int, n_samples: int,
                   channels: tuple[int, ...], viscous: bool, friction: bool, preload: bool, springs: bool,
                   dashpot: bool = False, law: str = "hertz"):
    """`run_full` with the books, on the host: advances the packed state `state0` (rows, B)
    of `batched._Layout` for the full step with the books (x, v, a; for elastic-plastic
    contacts every contact's largest overlap so far; every contact's largest total force; with damping, the viscous force on every body; the energy dissipated by
    damping and friction so far) and returns (the (B, n_samples) force traces, one per
    channel, N; the final packed state). The books' sums over the bodies follow
    `batched._step`'s order; the run is not differentiable (sweeps; fits call `run_full`).
    `dashpot`, `law` as for `run_full`."""
    _require("host")
    if dashpot and not viscous:
        raise ValueError("run_full_books: a dashpot needs viscous=True (the kernel's rates come with the damping).")
    _check_law(law, "host", "run_full_books")
    args = _full_args(p, state0, preload, springs, dashpot, law, "host") + (p["mass"],)
    attrs = {"dt": np.float64(dt_s), "steps_per_sample": np.int64(steps_per_sample), "viscous": np.int64(viscous),
             "friction": np.int64(friction), "extras": np.int64(preload or springs), "dashpot": np.int64(dashpot)}
    call = _Ffi("host", p["inv_mass"].shape[-2], n_samples)
    shapes = (jax.ShapeDtypeStruct(state0.shape, state0.dtype),) + call.trace_shapes(state0, len(channels))
    index = np.asarray(channels, dtype=np.int64)
    kind = f"books_{law}" if law != "hertz" else "books_dashpot" if dashpot else "books"
    state, *traces = call.call(kind, shapes, args, index, attrs)
    return tuple(traces), state


def _check_law(law: str, backend: str, caller: str) -> None:
    if law not in CONTACT_LAWS:
        raise ValueError(f"{caller}: law must be one of {CONTACT_LAWS}, got {law!r}.")
    if law != "hertz" and backend != "host":
        raise ValueError(f"{caller}: the {law} law runs on the host kernel (backend 'host').")


def _full_args(p: dict, state0, preload: bool, springs: bool, dashpot: bool, law: str, backend: str,
               sensors: tuple[int, ...] = ()) -> tuple:
    """The full kernels' arrays: the state, then the eight parameter arrays (zeros for the
    physics a run does not have) and, for the host kernels, the law's (`_law_array`) and the
    compliant sensors' (`_sensor_array`)."""
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
        # the linear dashpot (N s/m, `contact.contact_force`), zeros without one
        jax.numpy.reshape(p["dashpot"], (1, width(p["dashpot"]))) if dashpot else jax.numpy.zeros((1, 1)),
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
    """The law's parameters as the host kernels' (rows, 1 or B) array (`chain_kernel.cc`'s
    `LawRows`): Hertz's, two rows of zeros; the power law's exponent and reference overlap
    (m); Thornton's, every contact's yield force (N); Jackson-Green's, every contact's yield
    force, reduced radius (m) and Poisson ratio, then the yield stress (Pa) and the hardness
    ratio (`contact.JG_HARDNESS_RATIO`, the one `forces.elastic_parts` applies)."""
    if law == "hertz":
        return jax.numpy.zeros((2, 1))
    if law == "power_law":
        rows = [p["exponent"], p["reference_overlap_m"]]
    elif law == "thornton":
        rows = [p["yield_force_n"]]
    else:
        hardness = jax.numpy.full((1,), contact.JG_HARDNESS_RATIO)
        rows = [p["yield_force_n"], p["reduced_radius_m"], p["poisson"], p["yield_stress_pa"], hardness]
    rows = [jax.numpy.reshape(row, (-1, row.shape[-1]) if row.ndim > 1 else (1, -1)) for row in rows]
    width = max(row.shape[-1] for row in rows)
    return jax.numpy.concatenate([jax.numpy.broadcast_to(row, (row.shape[0], width)) for row in rows])


@functools.cache
def _full_call(config):
    """The full kernel for one configuration as a function of its arrays, with its JVP."""
    dt_s, steps_per_sample, n_samples, channels, viscous, friction, extras, dashpot, law, backend, sensors = config
    if dashpot and not viscous:
        raise ValueError("run_full: a dashpot needs viscous=True (the kernel's rates come with the damping).")
    # dashpot: the kernel with the dashpot's terms compiled in (`DASHPOT_DEFINE`)
    attrs = {"dt": np.float64(dt_s), "steps_per_sample": np.int64(steps_per_sample),
             "viscous": np.int64(viscous), "friction": np.int64(friction), "extras": np.int64(extras),
             "dashpot": np.int64(dashpot)}
    index = np.asarray(channels, dtype=np.int64)
    # the state, the eight parameter arrays (host: and the law's and the sensors')
    n_args = 11 if backend == "host" else 9
    # a dashpot on Hertz contacts: the dashpot library; on another law: that law's library;
    # compliant sensors (with or without a dashpot): the sensors' library
    if law != "hertz":
        kinds = (f"full_{law}", f"tangent_{law}")
    elif dashpot and not sensors:
        kinds = ("full_dashpot", "tangent_dashpot")
    else:
        kinds = ("full", "tangent")
    if sensors:
        kinds = tuple(f"{kind}_sensors" for kind in kinds)

    def ffi(args):
        return _Ffi(backend, args[1].shape[-2], n_samples)

    @jax.custom_batching.custom_vmap
    def traces(*args):
        call = ffi(args)
        shapes = call.trace_shapes(args[0], len(channels))
        return call.traces(call.call(kinds[0], shapes, args, index, attrs, sensors))

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
        out = call.call(kinds[1], out_shapes, primals + tangents, index, attrs, sensors)
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
