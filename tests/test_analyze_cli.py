"""`hertzchain synth` -> trace files -> `read_trace` and `hertzchain analyze` end to end."""

import json

import numpy as np
import pytest

from hertzchain.cli import main
from hertzchain.io.tracefile import read_trace


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth")
    code = main(
        [
            "synth",
            "--velocities",
            "0.15,0.3",
            "--contacts",
            "8,12",
            "--t-end",
            "2.4ms",
            "--sample-interval",
            "1us",
            "--noise-std",
            "0.37",
            "--seed",
            "4",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    return out


def test_synth_files_round_trip(synth_dir):
    listing = json.loads((synth_dir / "synth.json").read_text())
    assert [entry["file"] for entry in listing["files"]] == ["synth_v0.15.csv", "synth_v0.3.csv"]
    for entry, velocity in zip(listing["files"], (0.15, 0.3)):
        trace = read_trace(synth_dir / entry["file"])
        assert trace.striker_velocity_m_s == velocity
        assert trace.noise_std_n == pytest.approx(0.37)
        assert trace.contacts == (8, 12) and "wall" in trace.channels
        assert trace.header["x_true_eta_s"] == "0.0"
        assert trace.header["x_acq_seed"] == str(entry["seed"])
        assert len(trace.time_s) == 2400 and trace.sample_interval_s == pytest.approx(1e-6)
        # Before the wave arrives the record is the noise alone.
        quiet = trace.channels["contact_12"][trace.time_s < 0.25e-3]
        assert np.std(quiet) == pytest.approx(0.37, rel=0.15)
        setup = trace.setup()
        assert float(setup.striker_velocity_m_s) == velocity and setup.n_beads == 21
        assert (synth_dir / entry["file"].replace(".csv", ".png")).exists()


def test_analyze_recovers_the_velocity_law(synth_dir, tmp_path):
    files = sorted(str(p) for p in synth_dir.glob("*.csv"))
    assert main(["analyze", *files, "--out", str(tmp_path)]) == 0
    result = json.loads((tmp_path / "analysis.json").read_text())
    for summary in result["files"]:
        assert summary["incident_contacts"] == [8, 12]
        # Steel wall: F_wall/F_inc = 1.943 (noise-free reference), Eq. 5 says 1.741.
        assert summary["wall_force_ratio"] == pytest.approx(1.943, abs=0.02)
        assert summary["theory"]["wall_force_ratio_eq5"] == pytest.approx(1.741, abs=1e-3)
        check = summary["momentum_check"]["contact_12"]["ratio"]
        assert 1.0 < check < 1.05
    law = result["velocity_law"]
    assert law["velocity_constant"] == pytest.approx(201.37, rel=2e-3)
    labels = {(row["file"], row["channel"], row["label"]) for row in result["pulses"]}
    assert ("synth_v0.3.csv", "contact_8", "incident") in labels
    assert ("synth_v0.3.csv", "contact_8", "reflected") in labels
    assert ("synth_v0.3.csv", "wall", "wall") in labels
    rows = [r for r in result["pulses"] if r["label"] == "incident"]
    assert all(r["converged"] for r in rows)
    # 2 tau / (2R sqrt(10)/v) of the discrete pulse is 0.962 (fit threshold 0.05).
    for r in rows:
        speed = [s for s in result["files"] if s["file"] == r["file"]][0]["speed_m_s"]
        assert r["duration_s"] * speed / (2 * 0.013 * np.sqrt(10)) == pytest.approx(0.962, abs=0.01)
    csv_lines = (tmp_path / "pulses.csv").read_text().splitlines()
    assert csv_lines[0].startswith("file,channel,label,peak_time_s")
    assert len(csv_lines) == len(result["pulses"]) + 1
    for name in (
        "synth_v0.15_pulses.png",
        "synth_v0.3_pulses.png",
        "speed_duration.png",
        "restitution.png",
    ):
        assert (tmp_path / name).stat().st_size > 1000


def test_analyze_reports_bad_files(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("# format = hertzchain-trace/1\ntime_s,wall\n0,1\n")
    assert main(["analyze", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "missing header key" in capsys.readouterr().err


def test_repeated_shots_report_their_scatter(tmp_path):
    """Three shots at 0.3 m/s (and one at 0.15 m/s) differing only by their noise: grouped
    as repeats, with the sample standard deviation of their per-shot amplitudes and speeds."""
    import hertzchain as hc
    from hertzchain.acquisition import Acquisition, record_simulation
    from hertzchain.io.tracefile import write_trace

    paths = []
    for k, velocity in enumerate((0.3, 0.3, 0.15, 0.3)):
        setup = hc.ChainSetup(striker_velocity_m_s=velocity)
        run = hc.simulate(setup, t_end_s=1.2e-3, sample_interval_s=0.1e-6, contacts=(6, 11))
        trace = record_simulation(setup, run, Acquisition(noise_std_n=2.0), seed=k)
        paths.append(tmp_path / f"shot{k}.csv")
        write_trace(paths[-1], trace)
    out = tmp_path / "analysis"
    assert main(["analyze", *map(str, paths), "--out", str(out)]) == 0
    result = json.loads((out / "analysis.json").read_text())
    (group,) = result["repeats"]
    assert group["n_shots"] == 3 and group["velocity_m_s"] == pytest.approx(0.3)
    assert group["shots"] == "shot0.csv shot1.csv shot3.csv"
    per_shot = {s["file"]: s for s in result["files"]}
    for name in ("amplitude_n", "speed_m_s"):
        values = [per_shot[f][name] for f in ("shot0.csv", "shot1.csv", "shot3.csv")]
        assert group[f"{name}_mean"] == pytest.approx(np.mean(values), rel=1e-12)
        assert group[f"{name}_sd"] == pytest.approx(np.std(values, ddof=1), rel=1e-9)
    # noise of 2 N on a 300 N pulse: the amplitudes scatter by a few tenths of a newton
    assert 0.01 < group["amplitude_n_sd"] < 2.0
    assert (out / "repeats.csv").read_text().startswith("velocity_m_s,n_shots,shots,amplitude_n_mean")


def test_one_contact_channel_gives_amplitudes_and_says_why_no_speed(tmp_path, capsys):
    """Repeated shots with one contact channel (and the wall): the amplitude is measured
    (equal to the incident pulse's parabolic peak), the speed is not, and the output says
    why instead of printing NaN."""
    import hertzchain as hc
    from hertzchain.acquisition import Acquisition, record_simulation
    from hertzchain.io.tracefile import write_trace

    paths = []
    for k in range(2):
        setup = hc.ChainSetup(striker_velocity_m_s=0.3)
        run = hc.simulate(setup, t_end_s=1.2e-3, sample_interval_s=0.1e-6, contacts=(6,))
        trace = record_simulation(setup, run, Acquisition(noise_std_n=2.0), seed=k)
        paths.append(tmp_path / f"shot{k}.csv")
        write_trace(paths[-1], trace)
    out = tmp_path / "analysis"
    assert main(["analyze", *map(str, paths), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "nan" not in printed.lower()
    assert "no speed: the incident pulse is seen at one contact only (contact 6)" in printed
    assert "speed not measured in these shots" in printed
    result = json.loads((out / "analysis.json").read_text())
    peaks = [r["peak_force_n"] for r in result["pulses"] if r["channel"] == "contact_6" and r["label"] == "incident"]
    for summary, peak in zip(result["files"], peaks):
        assert summary["amplitude_n"] == pytest.approx(peak, rel=1e-12)
        assert "speed_m_s" not in summary and "two or more contacts" in summary["speed_not_measured"]
    (group,) = result["repeats"]
    assert group["speed_m_s_mean"] is None and group["amplitude_n_mean"] == pytest.approx(np.mean(peaks))
