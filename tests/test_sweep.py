"""Sweeps: grid parsing, resume after interruption, sharding, physics of the table."""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

import hertzchain as hc
from hertzchain.cli import main as cli_main
from hertzchain.sweep import SweepSpec, nonfinite_runs, parse_grid, read_sweep, run_sweep

N = 10


def _spec(**grid):
    grid = grid or {"striker_velocity_m_s": np.asarray([0.3, 0.6, 1.2]), "wall_youngs_pa": np.asarray([3e9, 4e11])}
    return SweepSpec(hc.ChainSetup(N), grid, t_end_s=0.8e-3, sample_interval_s=2e-6, contacts=(2, 6))


def test_parse_grid():
    name, values = parse_grid("striker_velocity_m_s=0.1:1:3:log")
    assert name == "striker_velocity_m_s"
    np.testing.assert_allclose(values, [0.1, 10**-0.5, 1.0])
    np.testing.assert_allclose(parse_grid("eta_s=0:2e-6:3")[1], [0.0, 1e-6, 2e-6])
    np.testing.assert_array_equal(parse_grid("wall_youngs_pa=3e9,45e9")[1], [3e9, 45e9])
    for bad in ("eta_s", "eta_s=", "eta_s=a,b", "eta_s=0:1", "v=0:1:3:cubic", "eta_s=0:1:3:log"):
        with pytest.raises(ValueError, match="grid"):
            parse_grid(bad)
    with pytest.raises(ValueError, match="bead_radius_m"):
        run_sweep(_spec(bead_radius_m=np.asarray([0.01])), "unused", progress=False)


def test_interrupted_sweep_resumes_to_the_same_table(tmp_path):
    spec = _spec()
    whole = run_sweep(spec, tmp_path / "whole", chunk_size=2, progress=False)
    assert whole.complete and whole.n_chunks == 3 and whole.computed == 3
    first = run_sweep(spec, tmp_path / "resumed", chunk_size=2, max_chunks=1, progress=False)
    assert not first.complete and first.chunks_done == 1
    assert not (tmp_path / "resumed" / "sweep.csv").exists()
    # A chunk half-written by a killed process leaves only a temporary file: ignored.
    (tmp_path / "resumed" / "chunks" / ".chunk_00001.parquet.123.tmp").write_bytes(b"partial")
    second = run_sweep(spec, tmp_path / "resumed", chunk_size=2, progress=False)
    assert second.complete and second.computed == 2
    for name in ("sweep.csv",):
        assert (tmp_path / "whole" / name).read_bytes() == (tmp_path / "resumed" / name).read_bytes()
    a, b = read_sweep(tmp_path / "whole"), read_sweep(tmp_path / "resumed")
    assert list(a) == list(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    # Running again computes nothing; a different sweep in the same folder is refused.
    assert run_sweep(spec, tmp_path / "whole", chunk_size=2, progress=False).computed == 0
    with pytest.raises(ValueError, match="different sweep"):
        run_sweep(spec._replace(t_end_s=1e-3), tmp_path / "whole", chunk_size=2, progress=False)
    # The finished table says what physics it holds: the base setup's hash and its fields.
    manifest = json.loads((tmp_path / "whole" / "manifest.json").read_text())
    assert set(a["setup_sha256"]) == {manifest["setup_sha256"]}
    assert set(a["setup.eta_s"]) == {0.0} and set(a["setup.bead_radius_m"]) == {0.013}
    assert "setup.wall_youngs_pa" not in a and "setup.striker_velocity_m_s" not in a  # swept: own columns
    assert np.all(a["result_finite"]) and np.all(a["peak_over_yield"] > 0)


def test_resume_with_other_physics_or_a_foreign_chunk_is_refused(tmp_path):
    spec = _spec()  # the shapes of the test above: its compiled program is reused
    first = run_sweep(spec, tmp_path / "a", chunk_size=2, max_chunks=1, progress=False, plots=False)
    assert first.chunks_done == 1
    for field, value, shown in (("mu", 0.3, "setup.mu = 0.0 there, 0.3 now"),
                                ("dashpot_n_s_m", 50.0, "setup.dashpot_n_s_m = 0.0 there, 50.0 now"),
                                ("contact_law", hc.laws.JacksonGreen(), 'setup.contact_law.class = "Hertz" there, '
                                                                        '"JacksonGreen" now')):
        other = spec._replace(setup=hc.ChainSetup(N, **{field: value}))
        with pytest.raises(ValueError, match=f"holds a different sweep \\({shown}\\).*--out"):
            run_sweep(other, tmp_path / "a", chunk_size=2, progress=False, plots=False)
    # A chunk from another sweep, or another chunk of this one, is refused by name.
    run_sweep(spec._replace(setup=hc.ChainSetup(N, mu=0.3)), tmp_path / "b", chunk_size=2, max_chunks=1,
              progress=False, plots=False)
    chunk = tmp_path / "a" / "chunks" / "chunk_00000.parquet"
    chunk.write_bytes((tmp_path / "b" / "chunks" / "chunk_00000.parquet").read_bytes())
    with pytest.raises(ValueError, match=r"chunk_00000.parquet is not chunk 0 \(runs 0:2\) of this sweep"):
        run_sweep(spec, tmp_path / "a", chunk_size=2, progress=False, plots=False)


def test_grid_values_are_checked_before_anything_runs(tmp_path):
    for grid, match in ((dict(eta_s=np.asarray([-1e-6, 1e-6])), r"grid: eta_s must be non-negative"),
                        (dict(wall_poisson=np.asarray([0.3, 0.7])), r"grid: wall_poisson must be in \(-1, 0.5\)"),
                        (dict(striker_velocity_m_s=np.asarray([-0.3])), "grid: striker_velocity_m_s must be positive"),
                        (dict(wall_youngs_pa=np.asarray([0.0])), "grid: wall_youngs_pa must be positive"),
                        (dict(dashpot_n_s_m=np.asarray([0.0, 1e6])),
                         r"grid: dashpot_n_s_m = 1e\+06 N s/m is beyond the stability of the time step")):
        with pytest.raises(ValueError, match=match):
            run_sweep(_spec(**grid), tmp_path, progress=False)
    assert not any(tmp_path.iterdir())


def test_nonfinite_rows_are_named():
    table = {"run": np.arange(4), "result_finite": np.asarray([True, False, True, False])}
    np.testing.assert_array_equal(nonfinite_runs(table), [1, 3])


def test_table_physics(tmp_path):
    table = run_sweep(_spec(), tmp_path, chunk_size=6, progress=False).table
    assert len(table["run"]) == 6
    np.testing.assert_array_equal(table["run"], np.arange(6))
    np.testing.assert_array_equal(table["striker_velocity_m_s"], [0.3, 0.3, 0.6, 0.6, 1.2, 1.2])
    # Dissipationless: the books balance to the integrator's error.
    assert np.all(np.abs(table["energy_error_rel"]) < 1e-4)
    assert np.all(table["dissipated_fraction"] == 0.0)
    # A stiffer wall pushes back harder (Job et al. Fig. 3a: ratio grows with wall modulus).
    soft, stiff = table["force_ratio"][0::2], table["force_ratio"][1::2]
    assert np.all(stiff > soft) and np.all(stiff > 1.5) and np.all(soft < 1.2)
    # Solitary-wave speed grows as F^(1/6) (Nesterenko): compare 0.3 and 1.2 m/s impacts.
    ratio = table["speed_m_s"][4] / table["speed_m_s"][0]
    expected = (table["incident_peak_n"][4] / table["incident_peak_n"][0]) ** (1 / 6)
    assert abs(ratio / expected - 1) < 0.02
    # The pulse is about five bead diameters long at these speeds (2 tau ~ 2R sqrt(10) / v).
    assert np.all(table["duration_contact_6_converged"])  # every cos^6 fit converged here
    width = table["duration_contact_6_s"] * table["speed_m_s"] / (2 * 0.013)
    assert np.all((width > 2.5) & (width < 3.5))
    for plot in ("force_ratio.png", "speed_vs_amplitude.png"):
        assert (tmp_path / plot).stat().st_size > 1000


_SHARDED = r"""
import sys, jax, numpy as np, hertzchain as hc
from hertzchain.sweep import SweepSpec, run_sweep
spec = SweepSpec(hc.ChainSetup(10, eta_s=1e-6), {"striker_velocity_m_s": np.asarray([0.3, 0.6, 1.2]),
                 "wall_youngs_pa": np.asarray([3e9, 4e11])}, t_end_s=0.8e-3, sample_interval_s=2e-6,
                 contacts=(2, 6))
run_sweep(spec, sys.argv[1] + "/four", chunk_size=4, progress=False, plots=False)
run_sweep(spec, sys.argv[1] + "/one", chunk_size=4, devices=jax.devices()[:1], progress=False, plots=False)
print(len(jax.devices()))
"""


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; the resumed sweep's equality stays in the default suite
def test_sharded_sweep_matches_unsharded(tmp_path):
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run(
        [sys.executable, "-c", _SHARDED, str(tmp_path)], capture_output=True, text=True, env=env, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip().splitlines()[-1] == "4"
    assert (tmp_path / "four" / "sweep.csv").read_bytes() == (tmp_path / "one" / "sweep.csv").read_bytes()
    manifest = json.loads((tmp_path / "four" / "manifest.json").read_text())
    assert manifest["n_runs"] == 6 and manifest["n_chunks"] == 2


def test_cli_resume(tmp_path, capsys):
    args = ["sweep", "--n-beads", "10", "--t-end", "0.8ms", "--sample-interval", "2us", "--contacts", "2,6",
            "--grid", "striker_velocity_m_s=0.3,1.2", "--grid", "eta_s=0,2e-6", "--chunk-size", "2",
            "--out", str(tmp_path), "--no-plots"]
    assert cli_main(args + ["--max-chunks", "1"]) == 0
    assert "1/2 chunks done" in capsys.readouterr().out
    assert cli_main(args) == 0
    captured = capsys.readouterr()
    assert "(4 runs, 1 chunk computed now)" in captured.out  # the second run computes the other chunk
    assert "2 of 4 runs exceed the yield force of contact 0" in captured.err  # 1.2 m/s, 2 GPa steel
    table = read_sweep(tmp_path)
    np.testing.assert_array_equal(table["eta_s"], [0.0, 2e-6, 0.0, 2e-6])
    np.testing.assert_array_equal(table["peak_over_yield"] > 1, [False, False, True, True])
    assert np.all(table["dissipated_fraction"][1::2] > 0.1) and np.all(table["dissipated_fraction"][0::2] == 0)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; the one-process sweep stays in it
def test_two_process_distributed_sweep_matches_one_process(tmp_path):
    """`--distributed` over two processes (jax.distributed, CPU collectives) on one machine:
    each computes every other chunk, process 0 writes the table, identical to one process."""
    args = ["sweep", "--n-beads", "10", "--t-end", "0.8ms", "--sample-interval", "2us", "--contacts", "2,6",
            "--grid", "striker_velocity_m_s=0.3,0.6,1.2", "--grid", "wall_youngs_pa=3e9,4e11",
            "--chunk-size", "2", "--no-plots"]
    assert cli_main(args + ["--out", str(tmp_path / "one")]) == 0
    port = _free_port()
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "hertzchain", *args, "--out", str(tmp_path / "two"), "--distributed",
             "--coordinator", f"127.0.0.1:{port}", "--num-processes", "2", "--process-id", str(k)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        )
        for k in range(2)
    ]
    outputs = [proc.communicate(timeout=300) for proc in procs]
    for proc, (out, err) in zip(procs, outputs):
        assert proc.returncode == 0, err[-2000:]
    assert "process 1: computed 1 chunk;" in outputs[1][0]
    assert "wrote" in outputs[0][0]
    assert (tmp_path / "two" / "sweep.csv").read_bytes() == (tmp_path / "one" / "sweep.csv").read_bytes()


def test_distributed_options_need_distributed(tmp_path, capsys):
    args = ["sweep", "--grid", "striker_velocity_m_s=0.3", "--num-processes", "2", "--out", str(tmp_path)]
    assert cli_main(args) == 2
    assert "--num-processes: only for a --distributed sweep" in capsys.readouterr().err
    assert not (tmp_path / "manifest.json").exists()
