"""Building the host and thread kernels' libraries (which ones: `libraries`): the compiler and its
flags, the library cache (its names, which digest everything a build reads, and its
pruning), the build records (`<library>.json`: size and SHA-256) that a cached library
must match before it is loaded, and the build itself (written whole or not at all, one
process at a time)."""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

from .libraries import CONTACT_LAW_DEFINES, CSRC, DRIVEN_SOURCE, HOST_LIBRARIES, SOURCE

try:
    import fcntl
except ImportError:  # not a POSIX system: builds are not serialised between processes
    fcntl = None

LAWS = CSRC / "chain_laws.h"  # the laws both kernels include
FFI_ARGS = CSRC / "chain_ffi.h"  # their handlers' argument lists

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
    """The host libraries this installation builds on this machine with these flags: those of
    `chain_kernel.cc` (`libraries.HOST_LIBRARIES`) and the driven chains'."""
    return {_library_path(library.defines) for library in HOST_LIBRARIES.values()} | {_library_path((), DRIVEN_SOURCE)}


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
    return ("-lmvec",) if vector_maths and f"-D{CONTACT_LAW_DEFINES['power_law']}" in defines else ()


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
        _compile_parts(source, [[*command, f"-DHC_PART={part}", "-c", "-o", str(out)]
                                for part, out in zip(SOURCE_PARTS, objects)])
        _compile(lambda partial: [compiler, *_flags(), *map(str, objects), "-o", str(partial), *_libraries(defines)],
                 path, source.name)


def _compile_parts(source: Path, commands) -> None:
    """Run the compiler `commands` at once, one process each; raise the first failure's
    error (`_compile_error`) once all have ended."""
    compiling = [subprocess.Popen(command, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
                 for command in commands]
    failed = [proc.communicate()[1] for proc in compiling]
    failed = [err for proc, err in zip(compiling, failed) if proc.returncode != 0]
    if failed:
        raise _compile_error(source.name, failed[0])


def check_source(defines: tuple[str, ...] = (), source: Path = SOURCE) -> None:
    """Compile `source` with `defines` (`-D` macros) through the compiler's front end only
    (`-fsyntax-only`: parsed, every template it uses instantiated, no code generated, nothing
    written), each of `chain_kernel.cc`'s `SOURCE_PARTS` at once: a compile error is raised
    as `_build` raises it. About 1 s a part where its build takes 7-14 s (2 cores)."""
    compiler = _cxx()
    if compiler is None:
        raise RuntimeError("no C++ compiler found (set CXX, or install g++)")
    command = [compiler, *_flags(), *defines, f"-I{jax.ffi.include_dir()}", str(source), "-fsyntax-only"]
    parts = SOURCE_PARTS if source == SOURCE else (None,)
    _compile_parts(source, [command + ([f"-DHC_PART={part}"] if part is not None else []) for part in parts])


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


def _instruction_set(arch: str) -> str:
    """The widest vector instructions the C++ compiler targets for `-march=arch`: "avx512",
    "avx2", "sse2", or the machine's name (`platform.machine()`) elsewhere."""
    macros = _compiler_macros(arch) or ""
    for name, macro in (("avx512", "__AVX512F__"), ("avx2", "__AVX2__"), ("sse2", "__SSE2__")):
        if macro in macros:
            return name
    return platform.machine().lower() or "unknown"
