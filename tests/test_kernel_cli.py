"""`hertzchain kernel`: builds the fused C++ kernel, or says why it cannot be used."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hertzchain import native


def _run(**environment):
    env = {**os.environ, **environment}
    return subprocess.run([sys.executable, "-m", "hertzchain", "kernel"], capture_output=True, text=True, env=env)


def test_switched_off_kernel_is_named_with_its_reason():
    done = _run(HERTZCHAIN_NATIVE="0")
    assert done.returncode == 0  # everything still runs, on the JAX kernel
    assert "HERTZCHAIN_NATIVE=0" in done.stdout and "JAX kernel" in done.stdout


def test_a_kernel_that_cannot_be_built_is_announced_once_and_its_reason_given_whole(tmp_path):
    # an empty library cache and a compiler that fails: the build is tried, and fails
    compiler = tmp_path / "failing-c++"
    compiler.write_text("#!/bin/sh\necho 'first line of the failure' >&2\necho 'second line' >&2\nexit 1\n")
    compiler.chmod(0o755)
    done = _run(CXX=str(compiler), HERTZCHAIN_CACHE=str(tmp_path / "cache"), HERTZCHAIN_NATIVE="1")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stderr.count("the fused C++ kernel is not available") == 1
    assert "the JAX kernel runs instead" in done.stderr
    assert "could not be built, in full" in done.stdout and "second line" in done.stdout
    assert "runs the JAX kernel instead" not in done.stdout  # said once, on stderr


@pytest.mark.skipif(not native.available(), reason=f"no C++ kernel here: {native.unavailable_reason()}")
def test_ready_kernel_names_its_build():
    done = _run()
    assert done.returncode == 0, done.stdout + done.stderr
    path = Path(done.stdout.split("ready (")[1].split(";")[0])
    assert path == native.library_path() and path.exists()


@pytest.mark.skipif(not native.available(), reason=f"no C++ kernel here: {native.unavailable_reason()}")
def test_all_also_loads_the_libraries_built_on_first_use(monkeypatch, capsys):
    """`--all` asks for the dashpot's library, every other law's and the compliant sensors' on
    each law (recorded, not built here: a build takes 14-20 s) and names each with its path."""
    import argparse

    from hertzchain.cli import kernel

    asked = []
    monkeypatch.setattr(native, "_load_dashpot", lambda: asked.append("dashpot"))
    monkeypatch.setattr(native, "_load_sensors", lambda law="hertz": asked.append(f"{law} sensors"))
    monkeypatch.setattr(native, "_load_law", lambda law: asked.append(law))
    assert kernel.run(argparse.Namespace(quiet=False, all=True, prune=False)) == 0
    assert asked == ["dashpot", "hertz sensors", *native.LAW_DEFINES, *(f"{law} sensors" for law in native.LAW_DEFINES)]
    out = capsys.readouterr().out
    for name in ("dashpot", "compliant sensors", *native.LAW_DEFINES, *(f"{law} compliant sensors"
                                                                        for law in native.LAW_DEFINES)):
        assert f"{name} library ready (" in out
    assert native._library_path((f"-D{native.LAW_DEFINES['thornton']}",)).name in out


def test_prune_keeps_the_newest_library_of_each_kind(tmp_path, monkeypatch, capsys):
    """`--prune`: of every kind of library (source, variant, chain length) the newest stays,
    and so does the library this installation builds here; older ones go with their lock
    files, and so do build folders older than an hour; the JAX cache, recent build folders
    and other files stay."""
    import argparse
    import time

    from hertzchain.cli import kernel

    monkeypatch.setenv("HERTZCHAIN_CACHE", str(tmp_path))
    now = time.time()

    def make(name, age_s, size=10):
        path = tmp_path / name
        path.write_bytes(b"x" * size)
        os.utime(path, (now - age_s, now - age_s))
        return path

    old = [make("chain_kernel-" + "a" * 16 + ".so", 900, 100), make("chain_kernel-" + "a" * 16 + ".so.lock", 900, 0),
           make("chain_thread-emulated-r12-" + "d" * 16 + ".so", 500, 30)]
    kept = [make("chain_kernel-" + "b" * 16 + ".so", 10), make("chain_kernel-" + "b" * 16 + ".so.lock", 10, 0),
            make("chain_kernel-sensor-" + "c" * 16 + ".so", 5000), make("chain_thread-emulated-r12-" + "e" * 16 + ".so", 20),
            make("chain_thread-emulated-r22-" + "f" * 16 + ".so", 9000), make("notes.txt", 9000),
            make(native.library_path().name, 5000)]  # this installation's, older than the "b" one
    (tmp_path / "jax").mkdir()
    kept.append(make("jax/entry", 9000))
    for name, age in (("tmpold", 7200.0), ("tmpnew", 60.0)):
        (tmp_path / name).mkdir()
        make(f"{name}/part1.o", age, 7)
        os.utime(tmp_path / name, (now - age, now - age))
    assert native.prune_cache(now) == (4, 137)  # 2 old libraries, a lock, a stale build's object file
    assert not any(path.exists() for path in old) and not (tmp_path / "tmpold").exists()
    assert all(path.exists() for path in kept) and (tmp_path / "tmpnew" / "part1.o").exists()
    assert native.prune_cache(now) == (0, 0)
    monkeypatch.setenv("HERTZCHAIN_NATIVE", "0")  # (no build into this folder, had none been loaded yet)
    assert kernel.run(argparse.Namespace(quiet=False, all=False, prune=True)) == 0
    assert f"pruned 0 superseded files (0.0 MiB) from {tmp_path}" in capsys.readouterr().out
