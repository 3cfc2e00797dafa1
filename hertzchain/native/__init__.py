"""The fused C++ kernels of the batched fast path (`chain_kernel.cc`), through `jax.ffi`.

XLA compiles the JAX kernel of `batched` into a few loops per step, each a pass over the
whole batch's state; `chain_kernel.cc` advances a block of 64 chains (8 for the rest of
the batch, then one at a time; tangent runs in blocks of 8) through all the steps of the run while their state stays in
the cache, computing every contact's force once per step (the loop structure of a
hand-written kernel). Two kernels, each specialised at compile time (C++ templates) for the
physics it runs, so that the conservative case pays nothing for the rest:

- the conservative one (`run`): Hertz contacts, sensor springs, preload, walls and free
  ends, with or without the books (running maxima, energies);
- the full one (`run_full`): the same plus Kuwabara-Kono damping and one law in the rate
  slot, a linear dashpot or velocity-squared dissipation (`laws.VelocitySquared`, in a
  library of its own on Hertz contacts; the total force clipped at 0), and track friction, the recorded forces only, and forward-mode tangents carried
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

The package, one concept a module: `libraries` (the table of host libraries: the physics
each runs, its macros and FFI targets, and which runs which physics), `build` (the compiler
and its flags, the library cache, build records and their verification, pruning),
`registry` (what this process loaded, could not load, and ran), `host` (loading the host
libraries, `kernel_for`),
`thread` (the one-thread-per-chain kernels) and `calls` (the kernels as JAX functions).
"""

# Beside the public names (`__all__`), the internal ones that `hertzchain.driven.fused`, `fitting`
# and the benchmarks call through the package (the `noqa`s); to replace one in a test, patch the
# module that defines it (e.g. `native.build._build`).
from .build import (  # noqa: F401
    ARCH_VARIABLE,
    BUILD_TIME_NOTE,
    FFI_ARGS,
    FLAGS,
    LAWS,
    SOURCE_PARTS,
    UNMASKED_FLAGS,
    _build,
    prune_cache,
)
from .calls import _fold_chains, _fold_directions, _unfold_chains, run, run_full, run_full_books  # noqa: F401
from .host import (  # noqa: F401
    BOOKS_TARGET,
    FIRST_USE_LIBRARIES,
    FULL_TARGET,
    KEPT_FREE_BYTES,
    MALLOC_VARIABLE,
    REUSED_BUFFER_BYTES,
    TANGENT_TARGET,
    TARGET,
    FusedKernel,
    _load,
    _load_host_library,
    _load_library,
    _load_named,
    available,
    build_libraries,
    cache_dir,
    check_libraries,
    kernel_for,
    library_path,
    library_table,
    unavailable_reason,
)
from .libraries import (
    CONTACT_LAW_DEFINES,
    CONTACT_LAWS,
    CSRC,
    DRIVEN_SOURCE,
    HOST_LIBRARIES,
    RATE_LAW_DEFINES,
    SENSOR_DEFINE,
    SOURCE,
    SYMBOLS,
    HostLibrary,
    host_library_for,
)
from .registry import JAX_INSTEAD, SWITCHED_OFF, kernel_record, note_use
from .thread import (  # noqa: F401
    EMULATION_FLAGS,
    NVCC_FLAGS,
    THREAD_FLAGS_VARIABLE,
    THREAD_SOURCE,
    _thread_library,
    _thread_target,
    thread_unavailable_reason,
)

__all__ = [
    "ARCH_VARIABLE", "BOOKS_TARGET", "BUILD_TIME_NOTE", "CONTACT_LAWS", "CONTACT_LAW_DEFINES", "CSRC",
    "DRIVEN_SOURCE", "EMULATION_FLAGS", "FFI_ARGS", "FIRST_USE_LIBRARIES", "FLAGS", "FULL_TARGET",
    "HOST_LIBRARIES", "JAX_INSTEAD", "KEPT_FREE_BYTES", "LAWS", "MALLOC_VARIABLE", "NVCC_FLAGS",
    "RATE_LAW_DEFINES", "REUSED_BUFFER_BYTES", "SENSOR_DEFINE", "SOURCE", "SOURCE_PARTS", "SWITCHED_OFF",
    "SYMBOLS", "TANGENT_TARGET", "TARGET", "THREAD_FLAGS_VARIABLE", "THREAD_SOURCE", "UNMASKED_FLAGS",
    "FusedKernel", "HostLibrary", "available", "build_libraries", "cache_dir", "check_libraries",
    "host_library_for", "kernel_for", "kernel_record", "library_path", "library_table", "note_use",
    "prune_cache", "run", "run_full", "run_full_books", "thread_unavailable_reason", "unavailable_reason",
]
