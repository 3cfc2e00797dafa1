"""Files as lab mates can read them, and no computation in float32."""

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from hertzchain.atomic import write_csv, write_json, write_text

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_files_are_created_with_the_users_umask(tmp_path, umask, mode):
    previous = os.umask(umask)
    try:
        write_text(tmp_path / "a.txt", "x\n")
        write_csv(tmp_path / "b.csv", ["time_s"], [[1.0]])
        write_json(tmp_path / "c.json", {"eta_s": 2e-6})
    finally:
        os.umask(previous)
    for name in ("a.txt", "b.csv", "c.json"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.csv", "c.json"]  # no temporaries


def _python(code: str, **environment) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), **environment}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=120)


def test_import_refuses_float64_switched_off_by_the_environment():
    result = _python("import hertzchain", JAX_ENABLE_X64="0")
    assert result.returncode != 0
    assert "Float64Error" in result.stderr
    assert "unset it (or set JAX_ENABLE_X64=1)" in result.stderr


def test_simulation_refuses_float64_switched_off_after_import():
    code = (
        "import jax, hertzchain as hc\n"
        "jax.config.update('jax_enable_x64', False)\n"
        "try:\n"
        "    hc.simulate(hc.ChainSetup(3), t_end_s=1e-5)\n"
        "except hc.precision.Float64Error as error:\n"
        "    print(error)\n"
        "try:\n"
        "    hc.driven.chain.DrivenChain(1.0, 1e9, 1.0, 0.0)\n"
        "except hc.precision.Float64Error as error:\n"
        "    print(error)\n"
        "try:\n"
        "    fitting.model.Problem([], [], [], None)\n"
        "except hc.precision.Float64Error as error:\n"
        "    print(error)\n"
    )
    result = _python("import hertzchain.driven.chain, fitting.model\n" + code)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("simulate: JAX's float64 is switched off")
    assert lines[1].startswith("DrivenChain: JAX's float64 is switched off")
    assert lines[2].startswith("the fit's Problem: JAX's float64 is switched off")
