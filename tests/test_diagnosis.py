"""Diagnosis: the candidate library's forward model, residual localisation, and the
workflow naming hidden effects (fast cases here; the per-candidate sweep is marked slow)."""

from __future__ import annotations

import dataclasses
import json
import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain  # noqa: F401
from fitting import effects as fx
from fitting.diagnosis import DiagnosisError, Step, diagnose, parse_model
from fitting.diagnosis.locate import cell, window_masks
from fitting.diagnosis.report import write_diagnosis_report
from fitting.hidden import NOMINAL, hidden_effect_traces, truth_fields
from hertzchain.chain import ChainSetup
from hertzchain.integrate import Recording, solve
from hertzchain.timegrid import choose_time_grid


# --- the library's forward model ------------------------------------------------------------------
def _extras(n_beads, **values):
    extras = dict(fx.effects_forward_model(n_beads).extras_defaults)
    for name, value in values.items():
        extras[fx.PREFIX + name] = jnp.asarray(value, dtype=jnp.float64)
    return extras


def _run(setup, extras, contacts=(2, 4), *, plastic=True):
    grid = choose_time_grid(setup, t_end_s=4e-4, sample_interval_s=1e-6)
    model = fx.effects_forward_model(setup.n_beads, plastic=plastic)
    return model.simulate(setup, grid, Recording(contacts=contacts), extras).forces_n, grid


def test_all_effects_off_is_the_base_model():
    setup = ChainSetup(6, striker_velocity_m_s=0.2)
    forces, grid = _run(setup, _extras(6))
    plain = solve(setup, grid, Recording(contacts=(2, 4)))
    for name in ("contact_2", "contact_4", "wall"):
        np.testing.assert_allclose(forces[name], plain.forces_n[name], rtol=0, atol=1e-9 * float(jnp.max(plain.forces_n[name])))


def test_effect_strengths_reach_the_setup():
    setup = ChainSetup(6, striker_velocity_m_s=0.2, wall_youngs_pa=100e9)
    extras = _extras(6, eta_s=1e-6, mu=0.1, mu_star=0.02, wall_softening=math.log(2.0), preload_n=3.0,
                     yield_softening=1.0, bead_radius_dev_3=0.01)
    changed = fx.apply_effects(setup, extras)
    assert float(changed.eta_s) == pytest.approx(1e-6)
    assert float(changed.mu) == pytest.approx(0.1)
    assert float(changed.mu_star) == pytest.approx(0.02)
    assert float(changed.wall_youngs_pa) == pytest.approx(50e9)
    assert float(changed.precompression_n) == pytest.approx(3.0)
    assert changed.plasticity
    assert float(changed.bead_yield_stress_pa) == pytest.approx(float(setup.bead_yield_stress_pa))
    ratio = np.asarray(changed.bead_mass_kg / setup.bead_mass_kg)
    np.testing.assert_allclose(ratio, [1, 1, 1.01**3, 1, 1, 1], rtol=1e-12)
    # yield_softening 0 never yields: identical to the elastic chain
    assert not np.isfinite(float(fx.apply_effects(setup, _extras(6)).bead_yield_stress_pa))


@pytest.mark.slow  # default-suite time on 2 cores; the effects-off model against solve stays in the default suite
def test_hertz_contact_model_equals_the_plastic_one_until_contacts_yield():
    setup = ChainSetup(6, striker_velocity_m_s=0.5)
    extras = _extras(6, eta_s=1e-6, wall_softening=0.5, bead_radius_dev_2=0.01)
    elastic, _ = _run(setup, extras, plastic=False)
    plastic, _ = _run(setup, extras)
    for name in ("contact_2", "contact_4", "wall"):
        np.testing.assert_allclose(elastic[name], plastic[name], rtol=0, atol=1e-12 * float(jnp.max(plastic[name])))
    # yield forces 1/27 of the nominal: the plastic model flattens the peaks, the Hertz one cannot
    yielding = dict(extras, **{fx.PREFIX + "yield_softening": jnp.asarray(3.0)})
    elastic, _ = _run(setup, yielding, plastic=False)
    plastic, _ = _run(setup, yielding)
    assert float(jnp.max(plastic["contact_2"])) < 0.9 * float(jnp.max(elastic["contact_2"]))


# A travelling sinusoid through a sensor bead: F_+ = A sin(w t), F_- = A sin(w (t + t0)).
_SINE_N, _SINE_HZ, _SINE_DELAY_S, _SINE_BETA = 50.0, 30e3, 49e-6, 0.11


def _travelling_sine(step_s, n):
    t = step_s * np.arange(n)
    w = 2 * np.pi * _SINE_HZ
    return t, _SINE_N * np.sin(w * t), _SINE_N * np.sin(w * (t + _SINE_DELAY_S))


def _eq4_closed_form(t, f0_hz):
    """Eq. 4 solved by hand for the travelling sinusoid, N: the steady state
    Im[m A e^(i w t)]/(1 - w^2/w0^2) with m = (1-beta) + beta e^(i w t0) (amplitude |m| A/(1 - w^2/w0^2),
    phase arg m), plus the free oscillation at w0 that starts the sensor as `sensor_signal` documents:
    F_s(0) = u(0) and dF_s/dt(0) the drive's first-interval slope."""
    w, w0 = 2 * np.pi * _SINE_HZ, 2 * np.pi * f0_hz
    mix = (1 - _SINE_BETA) + _SINE_BETA * np.exp(1j * w * _SINE_DELAY_S)
    gain = mix * _SINE_N / (1 - (w / w0) ** 2)
    steady = np.imag(gain * np.exp(1j * w * t))
    drive = np.imag(mix * _SINE_N * np.exp(1j * w * t))
    slope0 = (drive[1] - drive[0]) / (t[1] - t[0])
    free = (drive[0] - steady[0]) * np.cos(w0 * t) + (slope0 - w * np.real(gain)) / w0 * np.sin(w0 * t)
    return steady + free


def test_sensor_filter_matches_eq4_and_is_regular_at_infinite_f0():
    """`sensor_output` against Eq. 4 solved in closed form for a travelling sinusoid (30 kHz,
    t0 = 49 us, beta = 0.11, 0.1 us steps): the exact filter at f0 = 85 kHz to 1e-4 of the
    amplitude (the first-order hold's error, 3.6e-5), the first-order expansion at 2.2 MHz to
    2e-5 (its error 7e-6, its correction 1.5e-4); off, the contact force itself; d/d(rate) at 0 equal to
    w^2/w_ref^2 F_+ (-u''/w_ref^2) to 1e-5 inside the record."""
    step = 1e-7
    t, front, back = _travelling_sine(step, 2000)
    for f0, tolerance in ((85e3, 1e-4), (2.2e6, 2e-5)):
        rate = (fx.SENSOR_REFERENCE_HZ / f0) ** 2
        ours = np.asarray(fx.sensor_output(jnp.asarray(front), jnp.asarray(back), _SINE_BETA, rate, step))
        np.testing.assert_allclose(ours, _eq4_closed_form(t, f0), rtol=0, atol=tolerance * _SINE_N)
    off = fx.sensor_output(jnp.asarray(front), jnp.asarray(back), 0.0, 0.0, step)
    np.testing.assert_allclose(off, front, rtol=0, atol=1e-12 * _SINE_N)
    d_rate = jax.jacfwd(lambda r: fx.sensor_output(jnp.asarray(front), jnp.asarray(back), 0.0, r, step))(0.0)
    expected = (_SINE_HZ / fx.SENSOR_REFERENCE_HZ) ** 2 * front
    np.testing.assert_allclose(np.asarray(d_rate)[1:-1], expected[1:-1], rtol=0, atol=1e-5 * _SINE_N)
    assert np.all(np.isfinite(np.asarray(d_rate)))


@pytest.mark.slow
def test_jacobian_at_off_is_finite_for_every_strength():
    setup = ChainSetup(5, striker_velocity_m_s=0.2)
    grid = choose_time_grid(setup, t_end_s=3e-4, sample_interval_s=1e-6)
    model = fx.effects_forward_model(5)
    names = [n for n in model.extras_defaults]

    def out(values):
        extras = dict(zip(names, values))
        forces = model.simulate(setup, grid, Recording(contacts=(2,)), extras).forces_n
        return jnp.concatenate([forces["contact_2"], forces["wall"]])

    jac = jax.jacfwd(out)(jnp.zeros(len(names)))
    assert np.all(np.isfinite(np.asarray(jac)))
    by_name = dict(zip(names, np.abs(np.asarray(jac)).max(axis=0)))
    for name in ("dx_eta_s", "dx_mu", "dx_mu_star", "dx_sensor_beta", "dx_sensor_rate", "dx_wall_softening",
                 "dx_bead_radius_dev_2"):
        assert by_name[name] > 0, name


# --- localisation -------------------------------------------------------------------------------------
def test_window_masks_partition_the_record():
    t = np.arange(1000)
    model = 10 * np.cos(np.clip((t - 300) / 40, -np.pi / 2, np.pi / 2)) ** 6
    masks = window_masks(model)
    total = sum(m.astype(int) for m in masks.values())
    assert np.all(total <= 1)
    assert masks["peak"][300] and masks["before"][0] and masks["after"][999]
    assert not masks["peak"][200]
    c = cell(np.full(200, 2.0))
    assert c["chi2_per_sample"] == pytest.approx(4.0)
    assert c["excess_sigma"] == pytest.approx((800 - 200) / math.sqrt(400))


def test_bad_model_and_candidates_are_refused():
    with pytest.raises(DiagnosisError, match="model must be"):
        parse_model("hertz", 5)
    with pytest.raises(DiagnosisError, match="unknown effect"):
        parse_model("base+air_drag", 5)
    assert parse_model("base+viscous_damping", 5) == ["viscous_damping"]


def test_hidden_traces_carry_the_nominal_header():
    files = hidden_effect_traces({"wall_compliance": 20e9, "precompression": 2.0}, n_beads=5,
                                 velocities_m_s=(0.1,), contacts=(2,), t_end_s=3e-4, seed=1)
    header = files[0].header
    assert header["wall_youngs_pa"] == pytest.approx(203e9)
    assert "precompression_n" not in header
    assert files[0].channels["contact_2"][0] == pytest.approx(2.0, abs=6 * header["noise_std_n"])
    with pytest.raises(ValueError, match="unknown effect"):
        hidden_effect_traces(["air_drag"], n_beads=5)


def test_every_effect_can_be_hidden():
    """`NOMINAL` has a strength for every candidate effect and `truth_fields` turns each into
    fields of a valid chain (the confusion table hides every effect in turn)."""
    nominal = ChainSetup(6)
    for name in fx.EFFECT_NAMES:
        fields = truth_fields(nominal, {name: NOMINAL[name]}, np.random.default_rng(0))
        assert fields, name
        ChainSetup(6, **fields)


# --- the fits' solver ---------------------------------------------------------------------------
class _Linear:
    """Whitened residuals A x - y of a linear model, in the protocol of `least_squares`."""

    def __init__(self, a, y):
        self.a, self.y = a, y

    def residuals(self, x):
        return self.a @ x - self.y

    def linearize(self, x, columns):
        return self.residuals(x), self.a[:, columns]


def test_least_squares_frees_columns_and_weights_rows():
    """`fitting.fit.least_squares` against the closed-form linear least squares: columns 0 and
    2 free (sizes 10^5 apart), column 1 held, the last 10 rows weighted out."""
    from fitting.fit import least_squares

    rng = np.random.default_rng(3)
    a = rng.standard_normal((50, 3)) * [1.0, 1.0, 1e-5]
    truth = np.array([0.3, 0.1, 2e4])
    y = a @ truth + 0.01 * rng.standard_normal(50)
    y[40:] += 100.0  # rows that would pull the fit away if they were counted
    weights = np.ones(50)
    weights[40:] = 0.0
    result = least_squares(_Linear(a, y), np.array([0.0, 0.1, 0.0]), [0, 2], weights=weights,
                           tolerance=1e-6)
    rows = slice(0, 40)
    expected = np.linalg.lstsq(a[rows][:, [0, 2]], y[rows] - a[rows, 1] * 0.1, rcond=None)[0]
    assert result.converged
    assert result.x[1] == 0.1
    np.testing.assert_allclose(result.x[[0, 2]], expected, rtol=1e-9)
    r = weights * (a @ result.x - y)
    assert result.chi2 == pytest.approx(float(r @ r), rel=1e-9)


# --- the workflow -------------------------------------------------------------------------------------
SHORT = {"n_beads": 6, "contacts": (2, 4), "velocities_m_s": (0.03, 0.1, 0.3, 0.6), "sample_interval_s": 1e-6}


def _gap_at_noise(diagnosis):
    final = diagnosis.final
    return final["chi2"] - final["dof"] <= 3.0 * math.sqrt(2 * final["dof"])


@pytest.fixture(scope="module")
def viscous_short():
    files = hidden_effect_traces({"viscous_damping": 2e-6}, seed=5, noise_fraction=0.004, **SHORT)
    return diagnose(files, progress=False, max_effects=2)


@pytest.mark.slow  # default-suite time on 2 cores; a hidden effect named on the Verlet path (the diffrax path's soft wall stays in the default suite, tests/test_diagnosis_second_path.py)
def test_names_hidden_viscous_damping_on_a_short_chain(viscous_short):
    result = viscous_short
    assert result.missing_effects == ["viscous_damping"]
    step = result.steps[0]
    assert step.gap_before > 2.0
    assert step.gap_after < 1.1
    assert _gap_at_noise(result) and not result.misspecification
    eta = step.values["eta_s"]
    assert abs(eta - 2e-6) < max(4 * step.stderr["eta_s"], 0.1 * 2e-6)
    # the gap shrinks in the cells where viscous damping acts (peaks and tails)
    before = step.location_before["by_channel_window"]["contact_4"]
    after = step.location_after["by_channel_window"]["contact_4"]
    assert after["peak"]["chi2_per_sample"] < 0.5 * before["peak"]["chi2_per_sample"]


@pytest.mark.slow  # default-suite time on 2 cores; the report of the viscous diagnosis above (its fixture); the report's verdict rules stay in the default suite
def test_report_files(viscous_short, tmp_path):
    compiled = []  # the overlays' predictions: the diagnosis's compiled models, not the full one

    def listen(event, duration, fun_name=None, **_):
        if event.endswith("backend_compile_duration") and "model_vector" in str(fun_name):
            compiled.append(fun_name)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        paths = write_diagnosis_report(viscous_short, tmp_path)
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert compiled == [], compiled
    payload = json.loads(paths["json"].read_text())
    assert payload["missing_effects"] == ["viscous_damping"]
    step = payload["steps"][0]
    assert step["effect"] == "viscous_damping" and step["gap_after"] < step["gap_before"]
    assert step["fitted"]["eta_s"]["value"] > 0
    # every fit says how it ended: the named model's refit, the base and final fits, candidates;
    # the named model's refit starts where its candidate's fit ended, at its optimum, and stays
    assert step["converged"] is True and step["steps"] == 0
    assert payload["base_fit"]["converged"] is True and payload["final"]["converged"] is True
    assert payload["converged"] is True and payload["unconverged_fits"] == []
    assert payload["settings"]["nuisances"] == ["striker_velocity_m_s", "time_offset_s"]  # as a user writes them
    refitted = [c for c in step["candidates"] if c["chi2"] is not None]
    assert refitted and all(isinstance(c["converged"], bool) and c["steps"] > 0 for c in refitted)
    assert "viscous_damping" in paths["markdown"].read_text()
    for key in ("gap_png", "overlay_1"):
        assert paths[key].stat().st_size > 1000
    rows = paths["gaps_csv"].read_text().splitlines()
    assert rows[0].startswith("stage,channel,window")
    assert any(r.startswith("+viscous_damping,contact_2,peak") for r in rows)


@pytest.mark.slow
def test_nothing_hidden_names_nothing():
    files = hidden_effect_traces((), seed=11, noise_fraction=0.006, **SHORT)
    result = diagnose(files, progress=False)
    assert result.missing_effects == []
    assert not result.misspecification


EFFECT_CASES = {
    "viscous_damping": 1e-6,
    "track_friction": 0.19,
    "rotational_friction": 0.03,
    "sensor_dynamics": NOMINAL["sensor_dynamics"],
    "wall_compliance": 20e9,
    "bead_dispersion": 0.01,
    "precompression": 2.0,
    "plasticity": NOMINAL["plasticity"],
}


# `sensor_dynamics` data come from the core's split-bead mechanics (`ChainSetup.sensor_beads`),
# a different code path from the diagnosis's compliance form of the same sensor.
@pytest.mark.slow
@pytest.mark.parametrize("effect", list(EFFECT_CASES))
def test_each_hidden_effect_is_named(effect):
    files = hidden_effect_traces({effect: EFFECT_CASES[effect]}, n_beads=10, contacts=(3, 6),
                                 noise_fraction=0.005, seed=21)
    result = diagnose(files, progress=False, max_effects=2)
    assert result.missing_effects[:1] == [effect]
    assert result.steps[0].gap_after < result.steps[0].gap_before
    if effect == "bead_dispersion":
        # Known, open: the radii (1 % scatter) refit to the noise level on the first 70 % of
        # the records (chi^2 per sample 1.03 with 20 window steps) but not beyond (1.7 on the
        # first 85 %), so the whole-record refit stops at chi^2/dof 1.86. Named first all the
        # same; the noise-level claim is not made for it (README, Diagnosis).
        pytest.xfail("bead_dispersion on the 10-bead chain: named, refit ends above the noise level")
    assert _gap_at_noise(result)


@pytest.mark.slow
def test_two_hidden_effects_are_both_named():
    files = hidden_effect_traces({"viscous_damping": 1e-6, "wall_compliance": 20e9}, n_beads=10,
                                 contacts=(3, 6), noise_fraction=0.005, seed=31)
    result = diagnose(files, progress=False)
    assert sorted(result.missing_effects) == ["viscous_damping", "wall_compliance"]
    assert _gap_at_noise(result)


def _exponent_traces(exponent, *, n_beads=6, velocities=(0.05, 0.15, 0.4), noise_fraction=0.004, seed=0):
    """Traces of a chain whose contacts follow F = kappa_eff delta^exponent (outside the
    library), from a small velocity-Verlet integrator of its own; kappa_eff matches the Hertz
    force at a 10 um overlap so the pulses have the usual size."""
    from hertzchain.io.tracefile import TraceFile, setup_header

    rng = np.random.default_rng(seed)
    setup = ChainSetup(n_beads)
    kappa = float(setup.contact_kappa()[1])
    kappa_wall = float(setup.wall_kappa())
    scale = 1e-5 ** (1.5 - exponent)
    mass = np.concatenate([[float(setup.striker_mass_kg)], np.asarray(setup.bead_mass_kg)])
    k = np.full(n_beads, kappa * scale)
    dt, every, n_samples = 2e-8, 50, 700

    def forces(u):
        overlap = np.maximum(u[:-1] - u[1:], 0.0)
        contact = k * overlap**exponent
        wall = kappa_wall * scale * max(u[-1], 0.0) ** exponent
        net = np.concatenate([[0.0], contact]) - np.concatenate([contact, [wall]])
        return net, contact, wall

    files = []
    for v0 in velocities:
        u = np.zeros(n_beads + 1)
        v = np.zeros(n_beads + 1)
        v[0] = v0
        a = forces(u)[0] / mass
        rec = {f"contact_{c}": [] for c in (2, 4)} | {"wall": []}
        for _ in range(n_samples):
            for _ in range(every):
                v += 0.5 * dt * a
                u += dt * v
                a = forces(u)[0] / mass
                v += 0.5 * dt * a
            _, contact, wall = forces(u)
            rec["contact_2"].append(contact[2])
            rec["contact_4"].append(contact[4])
            rec["wall"].append(wall)
        channels = {name: np.asarray(values) for name, values in rec.items()}
        sigma = noise_fraction * max(float(np.max(c)) for c in channels.values())
        for name, values in channels.items():
            channels[name] = values + sigma * rng.standard_normal(n_samples)
        header = setup_header(ChainSetup(n_beads, striker_velocity_m_s=v0))
        header["noise_std_n"] = sigma
        files.append(TraceFile(header=header, time_s=dt * every * np.arange(1, n_samples + 1), channels=channels,
                               path=None))
    return files


@pytest.mark.slow
def test_contact_exponent_is_named_with_its_value():
    """Data of F ~ delta^1.6 from the test's own integrator (normalised to Hertz at 10 um,
    not where the diagnosis puts its reference): named contact_exponent alone, n to 0.01."""
    files = _exponent_traces(1.6)
    result = diagnose(files, progress=False)
    assert result.missing_effects == ["contact_exponent"]
    assert 1.5 + result.steps[0].values["exponent_shift"] == pytest.approx(1.6, abs=0.01)
    assert not result.misspecification


@pytest.mark.slow
def test_command_line_writes_the_report(tmp_path, monkeypatch, capsys):
    from hertzchain.cli import main
    from hertzchain.io.tracefile import write_trace

    files = hidden_effect_traces({"track_friction": 0.3}, seed=8, noise_fraction=0.004, **SHORT)
    paths = []
    for k, trace in enumerate(files):
        path = tmp_path / f"shot{k}.csv"
        write_trace(path, trace)
        paths.append(str(path))
    out = tmp_path / "out"
    assert main(["diagnose", *paths, "--model", "base", "--out", str(out), "--quiet"]) == 0
    payload = json.loads((out / "diagnosis.json").read_text())
    assert payload["missing_effects"] == ["track_friction"]
    assert payload["steps"][0]["gap_after"] < payload["steps"][0]["gap_before"]
    assert payload["converged"] is True
    assert main(["diagnose", *paths, "--model", "base+nonsense", "--out", str(out)]) == 2
    # fits held to one step reach no optimum: the command writes its report and exits 3, as fit does
    from fitting import diagnosis
    from fitting.fit import least_squares

    monkeypatch.setattr(diagnosis, "least_squares", lambda *a, **k: least_squares(*a, **dict(k, max_steps=1)))
    capsys.readouterr()
    assert main(["diagnose", *paths, "--candidates", "track_friction", "--out", str(out), "--quiet"]) == 3
    assert "hertzchain diagnose: error: no optimum reached by" in capsys.readouterr().err
    payload = json.loads((out / "diagnosis.json").read_text())
    assert payload["converged"] is False and "final fit" in " ".join(payload["unconverged_fits"])
    assert "NOT CONVERGED" in payload["conclusion"]


def test_local_band_sees_a_pulse_window_excess_that_a_low_global_chi2_hides():
    """`LOCAL_BAND_SIGMA` on the cells of `fitting.diagnosis.locate`: white noise in 15 channel x window
    cells (400 records) never reaches it, while residuals 0.67 sigma overall (a noise estimate
    1.5 x too large: chi^2/dof = 0.45) with a 3-sigma excess over a 100-sample pulse window do."""
    from fitting.diagnosis import LOCAL_BAND_SIGMA, NOISE_BAND_SIGMA
    from fitting.diagnosis.locate import cell

    rng = np.random.default_rng(4)
    sizes = [100, 300, 100, 300, 2000] * 3  # before, edges, peak, tail of three channels
    largest = max(max(cell(rng.standard_normal(n))["excess_sigma"] for n in sizes) for _ in range(400))
    assert largest < LOCAL_BAND_SIGMA
    cells = [cell(0.67 * rng.standard_normal(n)) for n in sizes]
    cells[2] = cell(0.67 * rng.standard_normal(100) + 3.0)  # the first channel's peak window
    n = sum(sizes)
    chi2 = sum(c["chi2"] for c in cells)
    assert chi2 / n < 0.6 and chi2 - n <= NOISE_BAND_SIGMA * math.sqrt(2 * n)  # hidden globally
    assert max(c["excess_sigma"] for c in cells) > LOCAL_BAND_SIGMA  # seen locally


class _CountingSearch:
    """What `_Workflow`'s verdict and conclusion read of a search: two base columns and one per
    strength, 1000 residuals, no folds (no held-out check), no law to interpret."""

    n_beads = 6
    folds: ClassVar[list] = []
    noise_estimate_variance = 0.0
    effect_columns: ClassVar = {"viscous_damping": [2], "track_friction": [3]}

    class problem:
        n_fitted = 1000

    def columns(self, effects):
        return [0, 1] + [c for e in effects for c in self.effect_columns[e]]

    def interpret(self, *args):
        return ""

    def log(self, text):
        pass


def _step(effect, converged, steps, candidates):
    location = {"worst": [], "by_frequency": {}}
    return Step(effect=effect, gap_before=3.0, gap_after=1.0, chi2_before=3000.0, chi2_after=1000.0,
                dof_before=998, dof_after=997, values={}, stderr={}, candidates=candidates,
                location_before=location, location_after=location, x_before=np.zeros(4), x_after=np.zeros(4),
                status={"converged": converged, "steps": steps})


def test_a_refit_without_an_optimum_is_named_so_in_the_verdict_and_the_conclusion():
    """A refit that reached no optimum: its verdict says so (a pass on a lower bound of its
    gain, a rejection that may not stand), unless the misfit is at the noise level anyway;
    the conclusion and `unconverged_fits` name the candidate's refit, the fit that added it
    (once, as the final fit) and a rejected refit; converged fits are not named."""
    from fitting.diagnosis import CandidateResult, _Workflow

    run = _Workflow(_CountingSearch(), "base", min_share=0.2, max_refits=3, progress=False)
    run.x, run.chi2, run.status = np.zeros(4), 3000.0, {"converged": True, "steps": 5}
    penalty = math.log(1000)
    strong = CandidateResult(effect="viscous_damping", n_parameters=1, score_chi2=2100.0, chi2=1000.0,
                             delta_chi2=2000.0, bic_gain=2000.0 - penalty, share_of_excess=2000.0 / 2002.0,
                             converged=False, steps=20, x=np.zeros(4))
    weak = dataclasses.replace(strong, effect="track_friction", chi2=2990.0, delta_chi2=10.0,
                               bic_gain=10.0 - penalty, share_of_excess=10.0 / 2002.0)
    judged = {c.effect: c for c in run.heldout_check([strong, weak])}
    assert judged["viscous_damping"].passed
    assert "did not converge within 20 steps (named on a lower bound of its gain)" in judged["viscous_damping"].reason
    assert not judged["track_friction"].passed
    assert judged["track_friction"].reason.startswith("removes only 0.5 % of the excess misfit")
    assert judged["track_friction"].reason.endswith("did not converge within 20 steps (the rejection may not stand)")
    converged = dataclasses.replace(strong, converged=True)
    assert "converge" not in run.heldout_check([converged])[0].reason
    run.chi2 = 1000.0  # at the noise level: the verdict does not rest on the refit
    assert run.heldout_check([strong])[0].reason == "the misfit is already at the noise level"

    run.chi2, run.status = 1000.0, {"converged": False, "steps": 20}
    run.steps = [_step("viscous_damping", False, 20, [judged["viscous_damping"]])]
    run.accepted, run.last_candidates = ["viscous_damping"], [judged["track_friction"]]
    notes = run.unconverged_fits(["viscous_damping"])
    assert notes == ["the refit of candidate viscous_damping (20 steps)",
                     "the fit with viscous_damping added (the final fit) (20 steps)"]
    _, text, _ = run.conclusion(["viscous_damping"], {"worst": [], "by_frequency": {}})
    assert "NOT CONVERGED: the refit of candidate viscous_damping (20 steps); the fit with" in text
    assert "(their rejection may not stand): track_friction." in text
    # everything converged: nothing said, nothing listed
    run.status = {"converged": True, "steps": 3}
    run.steps = [_step("viscous_damping", True, 3, [converged])]
    run.last_candidates = [dataclasses.replace(judged["track_friction"], converged=True)]
    assert run.unconverged_fits(["viscous_damping"]) == []
    assert "converge" not in run.conclusion(["viscous_damping"], {"worst": [], "by_frequency": {}})[1]


def test_noise_band_holds_chi2_whitened_by_noise_levels_estimated_from_pre_trigger_samples():
    """The band of a model that holds, on white noise whitened by sigmas each estimated from m
    samples (as the importer estimates them): 8 channels of 2650 samples, m = 250, 4000 draws
    of chi^2 = sum_c X_c / s_c, X_c ~ chi^2(n), s_c ~ chi^2(m - 1) / (m - 1). The band with
    `noise_estimate_variance` (read from the headers' `x_import_<channel>_noise_samples`) is left
    in under 1 % of the draws; the band of 2 dof alone in about a third of the draws
    (a false alarm at chi^2/dof ~ 1.03, as on imported scope files); a model 10 % off in
    amplitude still leaves it."""
    from fitting.data import make_experiment
    from fitting.diagnosis import NOISE_BAND_SIGMA, noise_estimate_variance
    from hertzchain.io.tracefile import TraceFile, setup_header

    n, m, channels = 2650, 250, ("wall", "contact_5")
    time = 1e-6 * np.arange(n)
    pulse = 100.0 * np.exp(-(((time - 1e-3) / 2e-5) ** 2))  # a record the files' checks accept
    stated_header = setup_header(ChainSetup(10, striker_velocity_m_s=0.1)) | {"noise_std_n": 1.0}
    files = []
    for shot in range(4):
        header = stated_header | {f"x_import_{c}_noise_samples": str(m) for c in channels}
        files.append(make_experiment(TraceFile(header, time, {c: pulse for c in channels})))
    variance = noise_estimate_variance(files)
    assert variance == pytest.approx(8 * 2 * n**2 / (m - 1), rel=1e-12)
    rng = np.random.default_rng(11)
    dof = 8 * n
    chi2 = np.sum(rng.chisquare(n, (4000, 8)) / (rng.chisquare(m - 1, (4000, 8)) / (m - 1)), axis=1)
    band = NOISE_BAND_SIGMA * math.sqrt(2 * dof + variance)
    assert np.mean(chi2 - dof > band) < 0.01  # 0.5 %: 1 / s_c skews the tail beyond a normal's 0.13 %
    assert np.mean(chi2 - dof > NOISE_BAND_SIGMA * math.sqrt(2 * dof)) > 0.25
    assert 1.21 * dof - dof > band  # residuals 10 % too large: still an alarm
    # one channel x window cell of 3000 such samples (`fitting.diagnosis.locate.cell`): its excess leaves
    # LOCAL_BAND_SIGMA in several % of the draws in white-noise units, rarely with the estimate's
    from fitting.diagnosis import LOCAL_BAND_SIGMA
    from fitting.diagnosis.locate import estimate_variance

    window = rng.chisquare(3000, 4000) / (rng.chisquare(m - 1, 4000) / (m - 1))
    assert np.mean((window - 3000) / math.sqrt(2 * 3000) > LOCAL_BAND_SIGMA) > 0.05
    assert np.mean((window - 3000) / math.sqrt(2 * 3000 + estimate_variance(3000, m)) > LOCAL_BAND_SIGMA) < 0.002
    residuals = rng.standard_normal(3000) * 1.1
    assert cell(residuals, estimate_variance(3000, m))["excess_sigma"] == pytest.approx(
        (float(residuals @ residuals) - 3000) / math.sqrt(6000 + 2 * 3000**2 / (m - 1)), rel=1e-12)
    # a file that states its noise adds nothing
    stated = make_experiment(TraceFile(stated_header, time, {"wall": pulse}))
    assert noise_estimate_variance([stated]) == 0.0


def _estimated_noise(files, samples: int, seed: int):
    """`files` as the importer leaves them: each channel's noise sigma estimated from `samples`
    noise-only samples (a pre-trigger segment), written with their count."""
    rng = np.random.default_rng(seed)
    for trace in files:
        sigma = float(trace.header["noise_std_n"])
        for name in trace.channels:
            trace.header[f"noise_std_n_{name}"] = float(np.std(sigma * rng.standard_normal(samples), ddof=1))
            trace.header[f"x_import_{name}_noise_samples"] = str(samples)
    return files


@pytest.mark.slow
def test_noise_band_with_estimated_noise_no_alarm_when_the_model_holds_an_alarm_when_it_does_not():
    """On a chain the rule was not tuned on (9 brass beads of 5 mm; the example's was 21 steel
    beads), channels whitened by noise levels estimated from 250 samples: with viscous
    damping hidden and a candidate for it, it is named and no alarm is raised; with track
    friction hidden too and no candidate for it, the alarm is raised."""
    from hertzchain.materials import BRASS

    brass = {"n_beads": 9, "contacts": (3, 6), "velocities_m_s": (0.05, 0.2, 0.6, 1.2), "sample_interval_s": 1e-6,
             "bead_radius_m": 5e-3, "bead_density_kg_m3": BRASS.density_kg_m3, "bead_youngs_pa": BRASS.youngs_pa,
             "bead_poisson": BRASS.poisson}
    held = _estimated_noise(hidden_effect_traces({"viscous_damping": 1.5e-6}, seed=21, noise_fraction=0.004,
                                                 **brass), 250, seed=22)
    result = diagnose(held, candidates=("viscous_damping", "track_friction"), max_effects=2, progress=False)
    assert result.missing_effects == ["viscous_damping"] and not result.misspecification
    missing = _estimated_noise(hidden_effect_traces({"viscous_damping": 1.5e-6, "track_friction": 0.3}, seed=21,
                                                    noise_fraction=0.004, **brass), 250, seed=22)
    result = diagnose(missing, candidates=("viscous_damping",), max_effects=1, progress=False)
    assert result.misspecification


def test_a_candidate_whose_score_reaches_the_noise_band_is_refitted_whatever_its_rank():
    """Screening ranks five candidates; the best `max_refits` = 3 are refitted, and so is the
    fourth, whose score alone would leave an excess of 3 (chi^2 3000 - 2000 on 997 dof) within
    the band 3 sqrt(2 x 997) = 134, not the fifth (an excess of 1003)."""
    from fitting.diagnosis import _Workflow

    class Screening(_CountingSearch):
        candidates: ClassVar = ["a", "b", "c", "d", "e"]
        effect_columns: ClassVar = {name: [2 + k] for k, name in enumerate(candidates)}

        def screen(self, x, effects, names):
            scores = {"a": 2900.0, "b": 2800.0, "c": 2700.0, "d": 2000.0, "e": 1000.0}
            return scores, {n: [x] for n in names}, {n: True for n in names}, []

    run = _Workflow(Screening(), "base", min_share=0.2, max_refits=3, progress=False)
    run.x, run.chi2, run.location = np.zeros(7), 3000.0, None
    assert run.screen()[4] == ["a", "b", "c", "d"]
    run.chi2 = 3200.0  # now "d" would leave 203 above its dof: outside the band
    assert run.screen()[4] == ["a", "b", "c"]


def test_a_round_at_the_noise_level_screens_nothing_and_refits_nothing():
    """At the noise level (chi^2 1000 on 993 dof: an excess of 7 in a band of 3 sqrt(2 x 993)
    = 134) the round neither screens (the screen would rank what is not refitted) nor refits:
    every candidate is reported as not screened, with a NaN score, none passes; above the band
    (chi^2 1200) the screen runs and ranks."""
    from fitting.diagnosis import _Workflow

    class Screening(_CountingSearch):
        def __init__(self):
            self.candidates = ["a", "b", "c"]
            self.effect_columns = {name: [2 + k] for k, name in enumerate(self.candidates)}
            self.screened = 0

        def screen(self, x, effects, names):
            self.screened += 1
            return {n: 100.0 for n in names}, {n: [x] for n in names}, {n: True for n in names}, []

    search = Screening()
    run = _Workflow(search, "base", min_share=0.2, max_refits=3, progress=False)
    run.x, run.chi2, run.location = np.zeros(5), 1000.0, {"worst": []}
    todo, scores, starts, separable, worth = run.screen()
    assert search.screened == 0 and worth == [] and all(math.isnan(scores[c]) for c in todo)
    results = run.heldout_check(run.refit(todo, scores, starts, separable, worth))
    assert [c.effect for c in results] == ["a", "b", "c"] and not any(c.passed for c in results)
    assert all(c.converged is None and "not screened" in c.reason for c in results)
    run.chi2 = 1200.0
    assert run.screen()[4] == ["a", "b", "c"] and search.screened == 1
