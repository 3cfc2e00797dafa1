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
    assert kernel.run(argparse.Namespace(quiet=False, all=True)) == 0
    assert asked == ["dashpot", "hertz sensors", *native.LAW_DEFINES, *(f"{law} sensors" for law in native.LAW_DEFINES)]
    out = capsys.readouterr().out
    for name in ("dashpot", "compliant sensors", *native.LAW_DEFINES, *(f"{law} compliant sensors"
                                                                        for law in native.LAW_DEFINES)):
        assert f"{name} library ready (" in out
    assert native._library_path((f"-D{native.LAW_DEFINES['thornton']}",)).name in out
