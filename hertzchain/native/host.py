"""The host's fused C++ kernels (`chain_kernel.cc` and its variants, `libraries.HOST_LIBRARIES`;
the driven chains' `driven_kernel.cc`): loading and registering each library (built on first
use), the libraries `hertzchain kernel` builds, and `kernel_for`, which fused kernel (if any)
runs a compiled kernel's physics."""

from __future__ import annotations

import concurrent.futures
import ctypes
import functools
import os
import platform
import time
from pathlib import Path
from typing import NamedTuple

import jax

from . import build, registry, thread
from .libraries import HOST_LIBRARIES, HostLibrary, host_library_for

# The FFI targets of the main library's runs (`libraries.HostLibrary.target` names every
# library's): the conservative step, and the full step's forces, tangents and books.
TARGET, FULL_TARGET, TANGENT_TARGET, BOOKS_TARGET = (
    HOST_LIBRARIES["chain"].target(kind) for kind in ("forward", "full", "tangent", "books"))


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


@functools.cache
def _load() -> str | None:
    """Build (if needed), load and register the kernel (and tune malloc for its results,
    `_keep_freed_buffers`): None on success, else why not (announced once by `_load_library`)."""
    def load():
        _keep_freed_buffers()
        _load_main()

    return registry.load_failure(load)


@functools.cache
def _load_main() -> Path:
    """Build (if needed), load and register the main library (`_load_library`): its path."""
    main = HOST_LIBRARIES["chain"]
    return _load_library(main.defines, main.what, main.targets,
                         instead="the JAX kernel runs instead, several times slower. "
                                 "hertzchain.native.unavailable_reason() gives the whole message; "
                                 "HERTZCHAIN_NATIVE=0 chooses the JAX kernel without this notice")


def _load_library(defines: tuple[str, ...], what: str, targets, source: Path = build.SOURCE, *,
                  instead: str = registry.JAX_INSTEAD) -> Path:
    """Build (if needed, `_ensure_built`) the host kernel `source` with `defines`, load it
    once it matches its build record and register its handler symbols as FFI targets
    (`targets`: (target, symbol) pairs); returns its path. A library that cannot be built or
    loaded raises RuntimeError or OSError, said once a process on stderr with the first line
    of why and `instead` (what runs in its place); later calls raise at once."""
    path = build._library_path(defines, source)
    if path in registry._FAILED:
        raise RuntimeError(registry._FAILED[path])
    if path not in registry._LOADED:
        try:
            digest = build._ensure_built(path, what, lambda out: build._build(out, defines, source))
            library = ctypes.cdll.LoadLibrary(str(path))
        except (OSError, RuntimeError) as error:
            registry._FAILED[path] = str(error) or type(error).__name__
            registry._announce_failure(what, error, instead)
            raise
        for name, symbol in targets:
            jax.ffi.register_ffi_target(name, jax.ffi.pycapsule(getattr(library, symbol)), platform="cpu")
        registry._LOADED[path] = digest
    return path


@functools.cache
def _load_host_library(library: HostLibrary) -> Path:
    """Build (if needed), load and register `library` (a `libraries.HOST_LIBRARIES` entry;
    all but the main library are built on their first use): its path."""
    if library.name == "chain":
        return _load_main()
    return _load_library(library.defines, library.what, library.targets)


def library_table() -> dict[str, tuple[tuple[str, ...], Path]]:
    """Every host library, by name: its `-D` macros and source. Those of `chain_kernel.cc`
    (`libraries.HOST_LIBRARIES`: "chain", the main library every run needs, and those built on
    their first use), then the driven chains' lock-in kernel ("driven", `hertzchain.driven.fused`)."""
    table = {name: (library.defines, build.SOURCE) for name, library in HOST_LIBRARIES.items()}
    table["driven"] = ((), build.DRIVEN_SOURCE)
    return table

# The libraries a first fit or diagnosis of impact data builds (measured: a diagnosis of a
# small chain from an empty cache), and a driven fit's; `hertzchain kernel` builds these.
FIRST_USE_LIBRARIES = ("chain", "dashpot", "compliant sensors", "jackson_green", "power_law",
                       "jackson_green compliant sensors", "driven")


def _load_named(name: str) -> Path:
    """Load the library `name` (`library_table`), building it where needed: its path."""
    if name == "driven":
        from ..driven import fused  # (the driven chains' kernel registers its own targets)

        return fused._library()
    return _load_host_library(HOST_LIBRARIES[name])


def _known_libraries(names) -> dict[str, tuple[tuple[str, ...], Path]]:
    """`library_table()`, once every name in `names` is checked to be one of its keys."""
    table = library_table()
    unknown = [name for name in names if name not in table]
    if unknown:
        raise ValueError(f"unknown kernel libraries {unknown}; known: {', '.join(table)}")
    return table


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
    table = _known_libraries(names)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    began = time.perf_counter()

    def build_one(name):
        defines, source = table[name]
        path = None
        try:
            path = build._library_path(defines, source)
            build._ensure_built(path, name, lambda out: build._build(out, defines, source), announce=False)
        except (OSError, RuntimeError) as error:
            return name, path, str(error) or type(error).__name__
        return name, path, None

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs or cores or 1)) as pool:
        for future in concurrent.futures.as_completed([pool.submit(build_one, name) for name in names]):
            name, path, why = future.result()
            if why is None:
                try:
                    _load_named(name)
                except (OSError, RuntimeError) as error:
                    why = str(error) or type(error).__name__
            yield name, path, time.perf_counter() - began, why


def check_libraries(names):
    """Compile the libraries `names` (`library_table` keys) through the compiler's front end
    only (`build.check_source`: what a build would refuse, refused in a tenth of its time;
    nothing is written or loaded). **Yields** (name, why) in the order of `names`: `why` is
    None where it compiles, else the whole message of its failure."""
    table = _known_libraries(names)
    for name in names:
        defines, source = table[name]
        try:
            build.check_source(defines, source)
        except (OSError, RuntimeError) as error:
            yield name, str(error) or type(error).__name__
        else:
            yield name, None


def available() -> bool:
    """Whether the kernel is built and registered (it builds it on the first call)."""
    return _load() is None


def unavailable_reason() -> str | None:
    """Why the kernel cannot be used, or None when it can."""
    return _load()


def cache_dir() -> Path:
    """Where the built libraries are kept: `$HERTZCHAIN_CACHE`, else `hertzchain` in
    `$XDG_CACHE_HOME` or `~/.cache`."""
    return build._cache_dir()


def library_path() -> Path:
    """Where this machine's build of the kernel is (or will be) kept."""
    return build._library_path()


class FusedKernel(NamedTuple):
    """A fused kernel: its physics, "conservative" (no damping or friction, books or not) or
    "full" (damping, friction, forward-mode tangents, the recorded forces only), and where
    it runs, "host" (`chain_kernel.cc`), "cuda" (`chain_kernel_thread.cu` on a GPU) or
    "emulated" (the CUDA kernel's source on the host, one thread after another: tests)."""

    physics: str
    backend: str


def host_library_of(flags) -> HostLibrary | None:
    """The host library that runs `flags`' physics (`batched.KernelFlags`: its contact law,
    its rate-slot law, compliant sensors or not), or None where none does
    (`libraries.host_library_for`)."""
    return host_library_for(flags.law, flags.rate_law, bool(flags.sensors))


def _host_library_loads(library: HostLibrary) -> bool:
    """Whether `library` loads; where it cannot be built, that was said once on stderr and
    its runs take the JAX kernel."""
    try:
        _load_host_library(library)
    except (OSError, RuntimeError):
        return False
    return True


def _platforms(devices) -> set[str]:
    """The platforms ("cpu", "gpu") of `devices`, or JAX's default one where none are given."""
    return {d.platform for d in devices} if devices else {jax.default_backend()}


def kernel_for(flags, devices, rows: int | None = None) -> FusedKernel | None:
    """Which fused kernel runs a compiled kernel's physics (`batched.KernelFlags`) on these
    devices, or None (the JAX kernel: laws other than Hertz's on a GPU, compliant sensors on
    a GPU or with the books, velocity-squared dissipation on a GPU, with compliant sensors
    or on another law than Hertz's, the books of damping or friction on a GPU, devices
    of another kind, no compiler, a library that cannot be built or loaded). `rows`: the
    kernel arrays' rows (bodies + 1); where given, the GPU's thread kernel for that chain
    length is built and loaded here, and one that cannot be (said once on stderr) gives None."""
    platforms = _platforms(devices)
    library = host_library_of(flags)
    if library is None or (flags.ledger and "books" not in library.kinds):
        return None
    # (a conservative chain on another law runs the full kernel: its library's only runs)
    physics = "full" if flags.full_state or library.law != "hertz" else "conservative"
    if platforms == {"cpu"} and available() and _host_library_loads(library):
        return FusedKernel(physics, "host")
    # the thread kernels: their libraries' chains, no books of the full step
    if not library.runs_on_threads or (flags.full_state and flags.ledger):
        return None
    if platforms == {"gpu"} and thread.thread_unavailable_reason("cuda") is None and (
            rows is None or thread._thread_library_loads("cuda", int(rows))):
        return FusedKernel(physics, "cuda")
    return None
