"""`hertzchain fit`: the command line end to end (files in, fit.json/CSV/PNG out)."""

import json

import numpy as np
import pytest

from fitting.parameters import bare_speed_constant
from fitting.synthetic import paper_setups, synthetic_traces
from hertzchain.cli import main
from hertzchain.io.tracefile import write_trace
from hertzchain.theory import long_wave_velocity_constant

TRUTH = {"eta": 2e-6, "mu": 0.19, "mu_star": 0.01}


@pytest.fixture(scope="module")
def trace_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("traces")
    setups = paper_setups([0.15, 0.3], **{"eta_s": TRUTH["eta"], "mu": TRUTH["mu"], "mu_star": TRUTH["mu_star"]})
    clean = synthetic_traces(setups, contacts=(5,), t_end_s=1.3e-3)
    sigma = [0.005 * max(np.max(v) for v in f.channels.values()) for f in clean]
    files = synthetic_traces(setups, contacts=(5,), t_end_s=1.3e-3, noise_std_n=sigma, seed=11)
    paths = []
    for k, trace in enumerate(files):
        path = folder / f"shot{k}.csv"
        write_trace(path, trace)
        paths.append(str(path))
    c_true = float(bare_speed_constant(setups[0])) * (1 + TRUTH["mu_star"]) ** (1 / 3)
    return paths, c_true


def test_fit_command_writes_the_report(trace_files, tmp_path, capsys):
    paths, c_true = trace_files
    out = tmp_path / "fit"
    code = main(["fit", *paths, "--params", "eta_s,mu,C", "--out", str(out), "--multistart", "2",
                 "--profile", "eta_s", "--quiet", "--per-trace-plots"])
    assert code == 0
    report = json.loads((out / "fit.json").read_text())
    params = report["params"]
    truth = {"eta_s": TRUTH["eta"], "mu": TRUTH["mu"], "C": c_true}
    for name, value in truth.items():
        assert abs(params[name]["value"] - value) < 3 * params[name]["stderr"], name
    assert report["correlation"]["names"] == ["eta_s", "mu", "C"]
    assert len(report["correlation"]["matrix"]) == 3
    assert set(report["residual_rms_n"]) == {"shot0", "shot1"}
    assert report["converged"] is True
    # which covariance, and why: chi^2/dof of right noise and model lies in the band
    assert report["covariance_scale"] == "noise" and "within" in report["covariance_reason"]
    low_band, high_band = report["noise_band_reduced_chi2"]
    assert low_band < report["reduced_chi2"] < high_band
    assert report["profiles"]["eta_s"]["all_converged"] is True
    assert len(report["starts"]) == 2
    # the speed constant: discrete value and the continuum one, C_t (1+mu*)^(1/3)
    speed = report["speed_constant"]
    # C_t of Eq. (3) from the beads' density and modulus, scaled as C: (C / C_0) C_t
    setup = paper_setups([0.3])[0]
    c_t = float(long_wave_velocity_constant(setup.bead_radius_m[0], setup.bead_density_kg_m3[0],
                                            setup.bead_youngs_pa[0], setup.bead_poisson[0]))
    c_0 = float(bare_speed_constant(setup))
    assert speed["C_continuum"] == pytest.approx(c_t * speed["C"] / c_0, rel=1e-9)
    assert speed["C_continuum"] == pytest.approx(198.92 * 1.01 ** (1 / 3), rel=2e-3)
    low, high = report["profiles"]["eta_s"]["interval_95"]
    assert low < TRUTH["eta"] < high
    for name in ("params.csv", "correlation.csv", "rms.csv", "starts.csv", "residuals_shot0.csv",
                 "overlay_shot0.png", "residuals_shot1.png", "correlation.png", "profile_eta_s.png",
                 "fit_summary.png"):
        assert (out / name).is_file(), name
    printed = capsys.readouterr().out
    assert "eta_s = " in printed and "converged" in printed


def test_fit_command_rejects_unknown_parameters(trace_files, capsys):
    paths, _ = trace_files
    assert main(["fit", paths[0], "--params", "eta_s,viscosity"]) == 2
    error = capsys.readouterr().err
    assert "Unknown parameter 'viscosity'" in error and "wall_youngs_pa" in error


def test_fit_help_lists_the_parameters_not_the_effect_strengths(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = capsys.readouterr().out
    assert "wall_youngs_pa" in text and "striker_velocity_m_s" in text
    assert "dx_" not in text
