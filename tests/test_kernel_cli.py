"""`hertzchain kernel`: builds the fused C++ kernel, or says why it cannot be used."""

import os
import shutil
import subprocess
import sys

import pytest

from hertzchain import native
from hertzchain.cli import kernel

_COMPILER = shutil.which("c++") or native.build._cxx()


def _run(**environment):
    env = {**os.environ, **environment}
    return subprocess.run([sys.executable, "-m", "hertzchain", "kernel"], capture_output=True, text=True, env=env, check=False)


def test_switched_off_kernel_is_named_with_its_reason():
    done = _run(HERTZCHAIN_NATIVE="0")
    assert done.returncode == 0  # everything still runs, on the JAX kernel
    assert "HERTZCHAIN_NATIVE=0" in done.stdout and "JAX kernel" in done.stdout


def _kernel_command(**options) -> int:
    import argparse

    return kernel.run(argparse.Namespace(**({"quiet": False, "all": False, "prune": False, "jobs": None} | options)))


def test_a_kernel_that_cannot_be_built_fails_the_command_with_its_reason_given_once(tmp_path, monkeypatch, capsys):
    # an empty library cache and a compiler that fails: every build is tried, and fails
    compiler = tmp_path / "failing-c++"
    compiler.write_text("#!/bin/sh\necho 'first line of the failure' >&2\necho 'second line' >&2\nexit 1\n")
    compiler.chmod(0o755)
    monkeypatch.setenv("CXX", str(compiler))
    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("HERTZCHAIN_NATIVE", raising=False)
    assert _kernel_command() == kernel.BUILD_FAILED == 4
    out = capsys.readouterr().out
    count = len(native.FIRST_USE_LIBRARIES)
    for name in native.FIRST_USE_LIBRARIES:  # each library's failure said once, whole
        assert out.count(f"] {name} FAILED (") == 1
    assert out.count("second line") == count and out.count("Why, in full:") == count
    assert f"{count} of {count} libraries failed" in out
    assert not list((tmp_path / "cache").glob("*.so"))  # nothing half-built left to load


def test_no_compiler_fails_the_command_saying_so(monkeypatch, capsys):
    monkeypatch.setattr(native.build, "_cxx", lambda: None)
    monkeypatch.delenv("HERTZCHAIN_NATIVE", raising=False)
    assert _kernel_command() == kernel.BUILD_FAILED
    out = capsys.readouterr().out
    assert "no C++ compiler found" in out and "JAX kernel instead" in out


@pytest.mark.slow  # builds the libraries of a first fit or diagnosis into the user's cache (minutes, once)
@pytest.mark.skipif(_COMPILER is None, reason="no C++ compiler: no kernel to build here")
def test_ready_kernel_names_its_build():
    assert native.available(), f"a C++ compiler is here but the kernel cannot be built: {native.unavailable_reason()}"
    done = _run(HERTZCHAIN_NATIVE="1")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "] chain (" in done.stdout and str(native.library_path()) in done.stdout
    assert f"ready, {len(native.FIRST_USE_LIBRARIES)} libraries" in done.stdout


@pytest.mark.parametrize("everything", [False, True])
def test_the_libraries_asked_for_are_built_with_a_progress_line_each(monkeypatch, capsys, everything):
    """By default the libraries a first fit or diagnosis needs, with `--all` every one; a
    line `[k/n] name (seconds)` as each is ready (builds recorded here, not run: one takes
    one to two minutes)."""
    asked = []

    def build(names, jobs):
        asked.extend(names)
        for k, name in enumerate(names):
            yield name, native.cache_dir() / f"{name}.so", 10.0 * k, None

    monkeypatch.setattr(native, "build_libraries", build)
    monkeypatch.setattr(native.build, "_cxx", lambda: "c++")
    monkeypatch.delenv("HERTZCHAIN_NATIVE", raising=False)
    assert _kernel_command(all=everything) == 0
    names = tuple(native.library_table()) if everything else native.FIRST_USE_LIBRARIES
    assert tuple(asked) == names and names[0] == "chain"
    out = capsys.readouterr().out
    for k, name in enumerate(names):
        assert f"[{k + 1}/{len(names)}] {name} ({10 * k} s) " in out
    assert set(native.FIRST_USE_LIBRARIES) < set(native.library_table())


def test_prune_keeps_the_newest_library_of_each_kind(tmp_path, monkeypatch, capsys):
    """`--prune`: of every kind of library (source, variant, chain length) the newest stays,
    and so does the library this installation builds here; older ones go with their lock
    files, and so do build folders older than an hour; the JAX cache, recent build folders
    and other files stay."""
    import time

    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
    now = time.time()

    def make(name, age_s, size=10):
        path = tmp_path / name
        path.write_bytes(b"x" * size)
        os.utime(path, (now - age_s, now - age_s))
        return path

    old = [make("chain_kernel-" + "a" * 16 + ".so", 900, 100), make("chain_kernel-" + "a" * 16 + ".so.lock", 900, 0),
           make("chain_thread-emulated-r12-" + "d" * 16 + ".so", 500, 30),
           make(".chain_kernel-" + "b" * 16 + ".so.json.123.tmp", 7200, 4)]
    kept = [make("chain_kernel-" + "b" * 16 + ".so", 10), make("chain_kernel-" + "b" * 16 + ".so.lock", 10, 0),
            make("chain_kernel-sensor-" + "c" * 16 + ".so", 5000), make("chain_thread-emulated-r12-" + "e" * 16 + ".so", 20),
            make("chain_thread-emulated-r22-" + "f" * 16 + ".so", 9000), make("notes.txt", 9000),
            make(native.library_path().name, 5000)]  # this installation's, older than the "b" one
    (tmp_path / "jax").mkdir()
    kept.append(make("jax/entry", 9000))
    kept.append(make(".chain_kernel-" + "b" * 16 + ".so.json.456.tmp", 60, 4))  # a record being written
    for name, age in (("tmpold", 7200.0), ("tmpnew", 60.0)):
        (tmp_path / name).mkdir()
        make(f"{name}/part1.o", age, 7)
        os.utime(tmp_path / name, (now - age, now - age))
    # 2 old libraries, a lock, a stale build's object file, a half-written build record
    assert native.prune_cache(now) == (5, 141)
    assert not any(path.exists() for path in old) and not (tmp_path / "tmpold").exists()
    assert all(path.exists() for path in kept) and (tmp_path / "tmpnew" / "part1.o").exists()
    assert native.prune_cache(now) == (0, 0)
    monkeypatch.setenv("HERTZCHAIN_NATIVE", "0")  # (no build into this folder, had none been loaded yet)
    assert _kernel_command(prune=True) == 0
    assert f"pruned 0 superseded files (0.0 MiB) from {tmp_path}" in capsys.readouterr().out
