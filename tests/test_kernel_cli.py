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
