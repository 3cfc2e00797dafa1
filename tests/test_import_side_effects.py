"""Importing the packages leaves JAX's backend unstarted, so that a program (or `hertzchain
sweep`, `hertzchain fit`) can still choose its devices afterwards (`jax.distributed.initialize`,
`jax_num_cpu_devices`), which JAX refuses once a computation has run."""

import subprocess
import sys

import pytest


@pytest.mark.parametrize("module", ["hertzchain", "fitting", "hertzchain.driven"])
def test_import_does_not_start_the_backend(module):
    code = (f"import {module}\n"
            "import jax._src.xla_bridge as bridge\n"
            "print('started' if bridge._backends else 'not started')")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "not started"
