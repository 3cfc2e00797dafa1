"""The library cache of the fused kernels (`hertzchain.native`): a library is loaded only once
it matches its build record (size and SHA-256), else it is named and built again; a library
that cannot be built is announced once and its runs take the JAX kernel; `kernel_record`
names the kernel that computed a result. Builds here are stand-ins (a copy of the library
this machine already built, or a failure): a real build takes one to two minutes."""

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hertzchain import native
from hertzchain.batched import KernelFlags

_COMPILER = shutil.which("c++") or native.build._cxx()
_SWITCHED_OFF = os.environ.get("HERTZCHAIN_NATIVE", "1") == "0"


def _built_library() -> Path:
    """This machine's main library, built (once, into the user's cache) where missing: where a
    compiler exists, a library that cannot be built fails the test."""
    if _COMPILER is None or _SWITCHED_OFF:
        pytest.skip("no C++ compiler (or HERTZCHAIN_NATIVE=0): no library to damage here")
    assert native.available(), f"a C++ compiler is here but the kernel cannot be built: {native.unavailable_reason()}"
    return native.library_path()


def _damage(path: Path, how: str) -> None:
    if how == "truncated":
        os.truncate(path, path.stat().st_size // 2)
    elif how == "empty":
        os.truncate(path, 0)
    elif how == "changed":  # same size, one byte different
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0xFF
        path.write_bytes(bytes(data))
    elif how == "no record":
        native.build._record_path(path).unlink()


@pytest.mark.parametrize("how, said", [("truncated", "holds 500 bytes where its build wrote 1000"),
                                       ("empty", "is empty"), ("changed", "its SHA-256 differs"),
                                       ("no record", "has no build record")])
def test_a_library_that_is_not_its_build_record_is_named_and_built_again(tmp_path, capsys, how, said):
    path = tmp_path / "chain_kernel-0123456789abcdef.so"
    built = []

    def build(out):
        built.append(out)
        out.write_bytes(bytes(range(250)) * 4)  # 1000 bytes

    digest = native.build._ensure_built(path, "a test library", build)
    assert digest == hashlib.sha256(path.read_bytes()).hexdigest()
    assert json.loads(native.build._record_path(path).read_text()) == {"library": path.name, "bytes": 1000, "sha256": digest}
    assert "compiling a test library into" in capsys.readouterr().err
    assert native.build._ensure_built(path, "a test library", build) == digest and len(built) == 1  # verified: kept
    _damage(path, how)
    assert native.build._check(path)[0] is not None and said in native.build._check(path)[0]
    assert native.build._ensure_built(path, "a test library", build) == digest and len(built) == 2
    err = capsys.readouterr().err
    assert err.count(f"the cached library {path} ") == 1 and said in err and "building it again" in err
    assert native.build._check(path) == (None, digest)


_SCRIPT = r"""
import shutil, sys
from pathlib import Path
from hertzchain import native
good = Path(sys.argv[1])
native.build._build = lambda path, defines=(), source=native.SOURCE: shutil.copy(good, path)  # a stand-in build
native.FIRST_USE_LIBRARIES = ("chain",)  # `hertzchain kernel`: the main library alone
from hertzchain.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _truncated_cache(tmp_path, size_bytes: int = 800000) -> tuple[Path, Path]:
    """A private cache holding this machine's main library, truncated to `size_bytes` after its
    build record was written: (the good library, the damaged copy)."""
    good = _built_library()
    cache = tmp_path / "cache"
    cache.mkdir()
    damaged = cache / good.name
    shutil.copy(good, damaged)
    native.build._write_record(damaged)
    os.truncate(damaged, size_bytes)
    return good, damaged


def _run_on(good: Path, damaged: Path, *command, said: str = "holds 800000 bytes where its build wrote"):
    env = dict(os.environ, HERTZCHAIN_CACHE=str(damaged.parent))
    env.pop("HERTZCHAIN_NATIVE", None)
    done = subprocess.run([sys.executable, "-c", _SCRIPT, str(good), *command], capture_output=True, text=True, check=False,
                          env=env, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    assert done.stderr.count(said) == 1 and "building it again" in done.stderr
    assert damaged.stat().st_size == good.stat().st_size and native.build._check(damaged)[0] is None
    return done


@pytest.mark.parametrize("size_bytes", [800000, 0])
def test_a_truncated_library_is_rebuilt_by_the_kernel_command(tmp_path, size_bytes):
    """`hertzchain kernel` on a cache whose library was truncated (before: SIGBUS, exit 135,
    no message) or emptied: it says so in one line, builds it again (here: a copy of the good
    one) and exits 0."""
    said = (f"{_built_library().name} is empty; building it again" if size_bytes == 0
            else "holds 800000 bytes where its build wrote")
    done = _run_on(*_truncated_cache(tmp_path, size_bytes), "kernel", said=said)
    assert "[1/1] chain (" in done.stdout and "ready, 1 library (" in done.stdout


@pytest.mark.slow
def test_a_sweep_on_a_truncated_library_rebuilds_it_and_names_it_in_its_manifest(tmp_path):
    good, damaged = _truncated_cache(tmp_path)
    _run_on(good, damaged, "sweep", "--n-beads", "6", "--t-end", "0.1ms", "--grid", "striker_velocity_m_s=0.2,0.4",
            "--no-plots", "--out", str(tmp_path / "out"))
    kernel = json.loads((tmp_path / "out" / "manifest.json").read_text())["kernel"]
    assert kernel["libraries"] == {good.name: hashlib.sha256(good.read_bytes()).hexdigest()}
    assert kernel["name"] in ("native-avx512", "native-avx2", "native-sse2") or kernel["name"].startswith("native-")


def _failing_build(path, defines=(), source=native.SOURCE):
    raise RuntimeError("compiling chain_kernel.cc failed:\nfirst line of the error\nsecond line")


def test_a_library_built_on_first_use_that_fails_is_announced_once_and_its_runs_take_the_jax_kernel(
        tmp_path, monkeypatch, capsys):
    _built_library()
    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
    monkeypatch.setattr(native.build, "_build", _failing_build)
    monkeypatch.setattr(native.registry, "_FAILED", {})
    monkeypatch.setattr(native.host, "_load_host_library", native.host._load_host_library.__wrapped__)
    flags = KernelFlags(viscous=True, springs=False, preload=False, rate_law="dashpot")
    for _ in range(3):
        assert native.kernel_for(flags, None) is None
    err = capsys.readouterr().err
    assert err.count("the fused chain kernel's dashpot runs cannot be used (compiling chain_kernel.cc failed:)") == 1
    assert "those runs take the JAX kernel instead" in err and "second line" not in err
    assert err.count("compiling the fused chain kernel's dashpot runs") == 1  # one try a process
    assert native.kernel_for(flags._replace(rate_law=None), None) == native.FusedKernel("full", "host")


def test_the_driven_kernel_that_cannot_be_built_is_announced_once(tmp_path, monkeypatch, capsys):
    from hertzchain.driven import fused

    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
    monkeypatch.delenv("HERTZCHAIN_NATIVE", raising=False)
    monkeypatch.setattr(native.build, "_build", _failing_build)
    monkeypatch.setattr(native.registry, "_FAILED", {})
    monkeypatch.setattr(fused, "_library", fused._library.__wrapped__)
    for _ in range(2):
        assert fused._load.__wrapped__() == "compiling chain_kernel.cc failed:\nfirst line of the error\nsecond line"
    err = capsys.readouterr().err
    assert err.count("the driven chains' fused lock-in kernel cannot be used (compiling chain_kernel.cc failed:)") == 1
    assert "the JAX kernel runs instead, about 7.5 times slower" in err


def test_libraries_are_built_at_once(tmp_path, monkeypatch):
    """Four builds of 0.5 s with four jobs end within about one build's time, each reported
    with its own time; a failed one is reported with its whole message."""
    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
    loaded = []
    monkeypatch.setattr(native.host, "_load_named", loaded.append)

    def build(path, defines=(), source=native.SOURCE):
        time.sleep(0.5)
        if defines == native.HOST_LIBRARIES["dashpot"].defines:
            raise RuntimeError("compiling chain_kernel.cc failed:\nwhole message")
        path.write_bytes(b"library")

    monkeypatch.setattr(native.build, "_build", build)
    names = ("chain", "dashpot", "thornton", "driven")
    began = time.perf_counter()
    done = {name: (seconds, why) for name, _, seconds, why in native.build_libraries(names, jobs=4)}
    assert time.perf_counter() - began < 1.4
    assert set(done) == set(names) and all(0.45 < seconds < 1.4 for seconds, _ in done.values())
    assert done["dashpot"][1] == "compiling chain_kernel.cc failed:\nwhole message"
    assert sorted(loaded) == sorted(set(names) - {"dashpot"})


def test_kernel_record_names_the_libraries_that_ran(monkeypatch):
    monkeypatch.setattr(native.registry, "_USED", {})
    monkeypatch.setattr(native.registry, "_FAILED", {})
    assert native.kernel_record() == {"name": "jax"}
    monkeypatch.setattr(native.build, "_compiler_macros", lambda arch: "#define __AVX2__ 1\n#define __SSE2__ 1\n")
    monkeypatch.setattr(native.registry, "_LOADED", {Path("/c/chain_kernel-a.so"): "ab" * 32, Path("/c/t-r8.so"): "cd" * 32})
    native.note_use(Path("/c/chain_kernel-a.so"))
    assert native.kernel_record() == {"name": "native-avx2", "libraries": {"chain_kernel-a.so": "ab" * 32}}
    native.note_use(Path("/c/t-r8.so"), "emulated")
    assert native.kernel_record()["name"] == "native-avx2+native-emulated"
    native.registry._FAILED[Path("/c/chain_kernel-dashpot-b.so")] = "compiling chain_kernel.cc failed:\nwhy"
    assert native.kernel_record()["name"] == "native-avx2+native-emulated+jax"  # the dashpot's runs: JAX
    assert native.kernel_record()["not_available"] == {"chain_kernel-dashpot-b.so": "compiling chain_kernel.cc failed:"}


def test_a_change_to_any_header_beside_the_source_names_a_new_library(tmp_path):
    """The cached library's name digests every header in the kernels' source folder, so that
    a change to any of them (the laws, the lanes, the step's phases, ...) builds a new one
    instead of loading a library built from the old code; nothing is compiled here."""
    folder = tmp_path / "csrc"
    shutil.copytree(native.CSRC, folder)
    source = folder / native.SOURCE.name
    before = native.build._library_path((), source)
    assert before == native.build._library_path((), source)  # the name is a function of the files
    headers = sorted(folder.glob("*.h"))
    assert {h.name for h in headers} >= {"chain_laws.h", "chain_step.h", "chain_full_block.h", "chain_lanes.h"}
    for header in headers:
        text = header.read_bytes()
        header.write_bytes(text + b"\n")
        assert native.build._library_path((), source) != before, header.name
        header.write_bytes(text)
    assert native.build._library_path((), source) == before
