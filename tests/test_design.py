"""Experiment design: Cramér–Rao predictions against the scatter of actual fits, singular
plans, the optimal-plan search, the command line and the worked example."""

import itertools
import json
import os
import runpy
import warnings
from pathlib import Path

import numpy as np
import pytest

import hertzchain as hc
from fitting import design as fd

VALUES = {"eta_s": 1.5e-6, "mu": 0.15, "mu_star": 0.03}
RUN = dict(noise_std_n=0.5, sample_interval_s=2e-6, t_end_s=0.5e-3)


@pytest.fixture(scope="module")
def small_setup():
    return hc.ChainSetup(6, eta_s=VALUES["eta_s"], mu=VALUES["mu"], mu_star=VALUES["mu_star"])


@pytest.fixture(scope="module")
def small_plan(small_setup):
    return fd.plan_experiments(small_setup, [0.3], channels=("contact_2", "wall"), **RUN)


@pytest.mark.slow  # default-suite time on 2 cores; a statistical check over many fits
def test_predicted_stderr_matches_the_scatter_of_fits():
    """Small variant (20 seeds): eta and C with friction fixed; the slow test does 60 seeds
    of eta, mu, C within 20 %."""
    values = dict(VALUES, mu=0.0)
    plan = fd.plan_experiments(hc.ChainSetup(6, eta_s=1.5e-6, mu_star=0.03), [0.3],
                               channels=("contact_2", "wall"), **RUN)
    scatter = fd.fit_scatter(plan, ("eta_s", "C"), values=values, n_seeds=20, chunk_size=20,
                             progress=False)
    assert scatter.n_converged == 20
    for p in ("eta_s", "C"):
        assert 0.65 < scatter.ratio[p] < 1.35, (p, scatter.ratio[p])
        assert abs(scatter.bias[p]) < 3 * scatter.predicted_stderr[p] / np.sqrt(20) + 1e-30
    # chi^2 of the fitted deviations in the predicted covariance: mean about p = 2
    d = scatter.estimates - np.array([scatter.truth[p] for p in scatter.params])
    chi2 = np.einsum("si,ij,sj->s", d, np.linalg.inv(scatter.design.covariance), d)
    assert 1.2 < chi2.mean() < 3.0


def test_singular_plan_names_the_parameters(small_setup):
    """Dissipationless chain: F(t; lambda kappa, V) = lambda^-2 F(t; kappa, lambda^2 V), so C
    cannot be told from a free striker velocity and free gains."""
    setup = hc.ChainSetup(6, mu_star=0.03)
    plan = fd.plan_experiments(setup, [0.3], channels=("contact_2", "wall"), **RUN)
    values = {"eta_s": 0.0, "mu": 0.0, "mu_star": 0.03}
    with pytest.raises(fd.DesignError, match=r"singular.*C, striker_velocity_m_s\[v1_0.3\], gain\["):
        fd.design(plan, ("C",), values=values, nuisances=("striker_velocity_m_s", "gain"))
    fixed = fd.design(plan, ("C",), values=values)  # known velocity and gains: C is determined
    assert 0 < fixed.relative_stderr["C"] < 1e-3


@pytest.mark.slow
def test_optimizer_finds_the_best_plan_and_beats_the_baseline(small_setup):
    baseline = [(0.3, "contact_2"), (0.3, "wall")]
    opt = fd.optimize_plan(
        small_setup, ("eta_s", "mu", "C"), candidate_velocities_m_s=[0.05, 0.3],
        candidate_channels=("contact_1", "contact_3", "wall"), size=2, values=VALUES,
        baseline_units=baseline, progress=False, **RUN,
    )
    units = [(v, c) for v in opt.candidates["velocities_m_s"] for c in opt.candidates["channels"]]
    best = -np.inf
    for pair in itertools.combinations(units, 2):
        try:
            best = max(best, opt.evaluate(pair).criterion["D"])
        except fd.DesignError:
            pass
    assert opt.recommended.criterion["D"] == pytest.approx(best, abs=1e-9)
    assert opt.recommended.criterion["D"] >= opt.baseline.criterion["D"]
    np.testing.assert_allclose(opt.evaluate(baseline).fisher, opt.baseline.fisher)
    # the baseline evaluated from the candidate blocks equals a direct design of that plan
    direct = fd.design(opt.experiments(baseline), ("eta_s", "mu", "C"), values=VALUES)
    for p in ("eta_s", "mu", "C"):
        assert direct.stderr[p] == pytest.approx(opt.baseline.stderr[p], rel=1e-9)
    # friction is seen best at low amplitude: the plan uses the slow impact
    assert any(v == 0.05 for v, _ in opt.chosen)
    assert opt.recommended.stderr["mu"] < opt.baseline.stderr["mu"]


def test_bad_design_input(small_plan):
    with pytest.raises(ValueError, match="Unknown parameter 'etaa'"):
        fd.design(small_plan, ("etaa",), values=VALUES)
    with pytest.raises(ValueError, match="unknown nuisance 'offset'"):
        fd.design(small_plan, ("eta_s",), values=VALUES, nuisances=("offset",))
    with pytest.raises(ValueError, match="eta_s is 0 in the plan's setup; give the value"):
        fd.design(small_plan, ("eta_s",), values={"mu": 0.1})
    with pytest.raises(ValueError, match="'contact_9' is not a channel of this chain"):
        fd.plan_experiments(hc.ChainSetup(6), [0.3], channels=("contact_9",), **RUN)
    with pytest.raises(ValueError, match="no pulse above"):  # the pulse never reaches the wall
        fd.plan_experiments(hc.ChainSetup(6), [0.3], channels=("wall",), noise_std_n=0.5,
                            sample_interval_s=2e-6, t_end_s=0.1e-3)


@pytest.mark.slow
def test_command_line(tmp_path):
    from hertzchain.cli import main

    out = tmp_path / "design"
    code = main([
        "design", "--n-beads", "6", "--eta", "1.5us", "--mu", "0.15", "--mu-star", "0.03",
        "--params", "eta_s,mu,C", "--velocities", "0.3", "--contacts", "2", "--noise-std", "0.5",
        "--sample-interval", "2us", "--t-end", "0.5ms", "--optimize", "2",
        "--candidate-velocities", "0.05,0.3", "--candidate-channels", "contact_1,contact_3,wall",
        "--out", str(out),
    ])
    assert code == 0
    data = json.loads((out / "design.json").read_text())
    assert set(data["params"]) == {"eta_s", "mu", "C"}
    assert data["params"]["C"]["unit"] == "m/s N^-1/6"
    assert data["correlation"]["names"] == ["eta_s", "mu", "C"]
    assert data["nuisances"]["free"] == []
    assert len(data["optimization"]["chosen"]) == 2
    assert data["optimization"]["recommended"]["params"]["mu"]["stderr"] <= data["params"]["mu"]["stderr"]
    assert (out / "design.png").stat().st_size > 0
    assert main(["design", "--n-beads", "6", "--params", "eta_s", "--out", str(out)]) == 2  # no plan


@pytest.mark.slow
def test_predicted_stderr_within_20_percent_and_recommended_plan_shrinks_scatter(small_setup):
    """60 noise seeds of eta, mu, C fitted by Levenberg-Marquardt, for a one-shot plan and for
    the D-optimal plan of the same size."""
    opt = fd.optimize_plan(
        small_setup, ("eta_s", "mu", "C"), candidate_velocities_m_s=[0.05, 0.3],
        candidate_channels=("contact_1", "contact_3", "wall"), size=2, values=VALUES,
        baseline_units=[(0.3, "contact_2"), (0.3, "wall")], progress=False, **RUN,
    )
    before = fd.fit_scatter(opt.experiments([(0.3, "contact_2"), (0.3, "wall")]), values=VALUES,
                            n_seeds=60, progress=False)
    after = fd.fit_scatter(opt.experiments(), values=VALUES, n_seeds=60, progress=False)
    for scatter in (before, after):
        assert scatter.n_converged >= 57
        for p in ("eta_s", "mu", "C"):
            assert abs(scatter.ratio[p] - 1) < 0.2, (p, scatter.ratio[p])
    assert after.empirical_std["mu"] < before.empirical_std["mu"]


@pytest.mark.slow
def test_worked_example_runs_at_small_size(tmp_path, monkeypatch):
    monkeypatch.setenv("HERTZCHAIN_EXAMPLE_SMALL", "1")
    monkeypatch.setenv("HERTZCHAIN_EXAMPLE_OUT", str(tmp_path))
    path = Path(__file__).resolve().parents[1] / "examples" / "05_design_eta_mu.py"
    with warnings.catch_warnings():
        runpy.run_path(str(path), run_name="__main__")
    data = json.loads((tmp_path / "05_design.json").read_text())
    assert data["criterion"] == "D"
    assert (tmp_path / "05_design_single_recordings.png").stat().st_size > 0
    ratio = data["stderr_ratio_recommended_over_baseline"]
    assert ratio["mu"] < 1 and ratio["eta_s"] < 1.5
    assert os.path.exists(tmp_path / "05_design_plans.png")
