"""Streamed lock-in sweeps: chunks on disk, resume, the same numbers as one batch, sharding."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from helpers import lydon_bead

from hertzchain.driven import lockin_grid
from hertzchain.driven.grid_sweep import read_lockin_sweep, run_lockin_sweep

OPTIONS = {"harmonics": (1.0, 0.5), "ramp_periods": 5, "hold_periods": 8, "window_periods": 2,
           "steps_per_period": 32}


def test_sweep_resumes_and_matches_one_batch(tmp_path):
    chain = lydon_bead(precompression_n=0.133, damping_rate_per_s=1280.0)
    frequencies = np.linspace(2500.0, 3100.0, 5)
    amplitudes = np.array([1e-9, 4e-9, 8e-9])
    first = run_lockin_sweep(chain, frequencies, amplitudes, tmp_path, chunk_size=4, max_chunks=2, progress=False,
                             **OPTIONS)
    assert not first.complete and first.chunks_done == 2 and first.n_chunks == 4
    stamp = (tmp_path / "chunks" / "chunk_00000.parquet").stat().st_mtime_ns
    done = run_lockin_sweep(chain, frequencies, amplitudes, tmp_path, chunk_size=4, progress=False, **OPTIONS)
    assert done.complete and done.computed == 2
    assert (tmp_path / "chunks" / "chunk_00000.parquet").stat().st_mtime_ns == stamp  # not recomputed
    direct = lockin_grid(chain, frequencies, amplitudes, **OPTIONS)
    # each run is its own column of the batch, so batch size does not change a run's numbers
    np.testing.assert_allclose(np.asarray(done.grid.complex_amplitude), np.asarray(direct.complex_amplitude),
                               rtol=1e-12, atol=1e-12 * float(np.abs(direct.complex_amplitude).max()))
    again = read_lockin_sweep(tmp_path)
    np.testing.assert_allclose(np.asarray(again.rms), np.asarray(direct.rms), rtol=1e-12)
    header = (tmp_path / "lockin.csv").read_text().splitlines()[0].split(",")
    assert header == ["run", "frequency_hz", "drive_amplitude_m", "rms_1f", "phase_1f_rad", "rms_0.5f",
                      "phase_0.5f_rad"]
    assert (tmp_path / "lockin.png").stat().st_size > 0
    with pytest.raises(ValueError, match="differs in: drive_amplitudes_m"):
        run_lockin_sweep(chain, frequencies, amplitudes * 2, tmp_path, chunk_size=4, progress=False, **OPTIONS)


_SHARDED = f"""
import json, sys
import jax, numpy as np
sys.path.insert(0, "tests")
from helpers import lydon_bead
OPTIONS = {OPTIONS!r}
from hertzchain.driven.grid_sweep import run_lockin_sweep
assert len(jax.devices()) == 2
chain = lydon_bead(precompression_n=0.133, damping_rate_per_s=1280.0)
out = run_lockin_sweep(chain, np.linspace(2500.0, 3100.0, 5), np.array([1e-9, 4e-9, 8e-9]), sys.argv[1],
                       chunk_size=6, progress=False, plots=False, **OPTIONS)
print(json.dumps([np.asarray(out.grid.complex_amplitude).real.tolist(), np.asarray(out.grid.complex_amplitude).imag.tolist()]))
"""


def test_sharded_sweep_gives_the_same_numbers(tmp_path):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SHARDED, str(tmp_path / "sharded")], capture_output=True, text=True,
                          env=env, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    real, imag = json.loads(proc.stdout.strip().splitlines()[-1])
    sharded = np.asarray(real) + 1j * np.asarray(imag)
    chain = lydon_bead(precompression_n=0.133, damping_rate_per_s=1280.0)
    direct = lockin_grid(chain, np.linspace(2500.0, 3100.0, 5), np.array([1e-9, 4e-9, 8e-9]), **OPTIONS)
    np.testing.assert_allclose(sharded, np.asarray(direct.complex_amplitude), rtol=1e-12,
                               atol=1e-12 * float(np.abs(direct.complex_amplitude).max()))


def test_sweep_reads_out_with_the_grid_keywords_and_defaults(tmp_path):
    # the read-out keywords and defaults are lockin_grid's (as the grid module's docstring
    # states them); a misspelt one is refused by name, before anything runs
    from hertzchain.driven.grid import readout_options

    assert readout_options("test") == {"bead": 1, "quantity": "velocity", "harmonics": (1.0, 0.5),
                                       "ramp_periods": 25, "hold_periods": 35, "window_periods": 4,
                                       "steps_per_period": 64, "contact": None}
    chain = lydon_bead(precompression_n=0.133, damping_rate_per_s=1280.0)
    with pytest.raises(TypeError, match="run_lockin_sweep: unknown keyword.*windows_periods"):
        run_lockin_sweep(chain, [3000.0], [1e-9], tmp_path, progress=False, windows_periods=4)
    assert not (tmp_path / "manifest.json").exists()
