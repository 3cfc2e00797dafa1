"""The diagnosis's models on the batched kernel: `fitting.effects.EffectsSimulation` with rigid
sensor beads and without the dashpot effect (its twin) is a `fitting.model.KernelForm`, which
the C++ kernel runs; it must give the numbers of the full model on `solve` under `vmap` where
the sensors' compliance and the dashpot are 0, values and derivatives, and the diagnosis's
evaluator must choose it only where that holds. The full model with compliant sensors runs
the C++ kernel's sensor library on Hertz contacts: it must give `solve`'s numbers everywhere.
Data: a 7-bead brass-like chain (not the paper's), two shots, contacts 2 and 5."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fitting import effects as fx
from fitting.diagnosis import _Evaluator
from fitting.fit import initial_values, make_problem
from fitting.hidden import hidden_effect_traces
from fitting.model import Problem, residuals_and_jacobian
from fitting.parameters import ParameterInstance, get_spec

EXTRAS = ("eta_s", "dashpot_n_s_m", "preload_n", "preload_seen", "sensor_beta", "sensor_rate", "sensor_coupling",
          "yield_softening", "wall_softening")


@pytest.fixture(scope="module")
def brass_files():
    return hidden_effect_traces((), n_beads=7, velocities_m_s=(0.15, 0.5), contacts=(2, 5), seed=2,
                                bead_radius_m=5e-3, bead_density_kg_m3=8500.0, bead_youngs_pa=110e9,
                                t_end_s=6e-4)


def _problem(files, solve=False, **law):
    """The diagnosis's model of `files` (on `solve` under `vmap` with `solve`, else on the
    batched kernel) and a point: the base fit's start, every effect off."""
    forward = fx.effects_forward_model(7, **law)
    if solve:
        forward = dataclasses.replace(forward, kernel=None)
    seed = make_problem(files, ("eta_s", "C", "striker_velocity_m_s"), forward=forward)
    extra = [ParameterInstance(get_spec(fx.PREFIX + name), label=name) for name in EXTRAS]
    problem = Problem(seed.experiments, tuple(seed.instances) + tuple(extra), seed.base_setups, forward)
    return problem, np.concatenate([initial_values(seed), np.zeros(len(extra))])


def _assert_twin_equals(twin, full, x, skipped):
    """The twin's residuals equal the full model's at `x` to 1e-12 of their largest, and every
    Jacobian column but those labelled `skipped` (each not 0) to 1e-8 of its largest."""
    wanted = [c for c in range(x.size) if full.labels[c] not in skipped]
    r_ref, j_ref = residuals_and_jacobian(full, x, wanted)
    r, j = residuals_and_jacobian(twin, x, wanted)
    assert np.max(np.abs(r - r_ref)) <= 1e-12 * np.max(np.abs(r_ref))
    scale = np.max(np.abs(j_ref[:, wanted]), axis=0)
    assert np.all(scale > 0)
    assert np.all(np.max(np.abs(j[:, wanted] - j_ref[:, wanted]), axis=0) <= 1e-8 * scale)


# The Hertz case runs with `-m slow` (suite time); the yielding one, which runs the same
# twin through the elastic-plastic library as well, stays in the default suite.
# both with `-m slow` (default-suite time; test_evaluator below holds which model the kernel twin stands for)
@pytest.mark.parametrize("plastic", [pytest.param(False, marks=pytest.mark.slow), pytest.param(True, marks=pytest.mark.slow)])
def test_twin_on_the_kernel_equals_the_full_model_at_zero_compliance_and_dashpot(brass_files, plastic):
    """Effects on (extra damping, a preload half seen, sensors' Eq. 4 at f0 = 183 kHz and,
    with `plastic`, yield forces 1/512 of the nominal, which the contacts cross), the
    sensors' coupling and the dashpot 0: residuals to 1e-12 of their largest and every
    Jacobian column to 1e-8 of its largest (measured on the paper's chain: 4e-14, and 2e-9
    for the sensors' rate, whose filter takes a second difference of the forces); the
    coupling's column (rate 0 there) is 0 in both."""
    compliant, x = _problem(brass_files, solve=True, plastic=plastic)
    rigid, _ = _problem(brass_files, plastic=plastic, compliant_sensors=False, dashpot=False)
    # (compliant sensors run the C++ sensor libraries, the law's)
    assert rigid.simulates_natively() and not compliant.simulates_natively()
    assert _problem(brass_files, plastic=plastic)[0].simulates_natively()
    for name, value in (("eta_s", 3e-7), ("preload_n", 0.5), ("preload_seen", 0.5), ("sensor_beta", 0.2),
                        ("sensor_rate", 0.3), ("yield_softening", 8.0 if plastic else 0.0)):
        x[compliant.labels.index(name)] = value
    coupling = compliant.labels.index("sensor_coupling")
    # (on Hertz contacts the yield's column is 0 in both)
    _assert_twin_equals(rigid, compliant, x, ("sensor_coupling", "dashpot_n_s_m") + (() if plastic else
                                                                                   ("yield_softening",)))
    x[compliant.labels.index("sensor_rate")] = 0.0
    _, j_ref = residuals_and_jacobian(compliant, x, [coupling])
    _, j = residuals_and_jacobian(rigid, x, [coupling])
    assert np.all(j_ref[:, coupling] == 0.0) and np.all(j[:, coupling] == 0.0)


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it
def test_dashpot_twin_on_the_kernel_equals_the_full_model_at_zero_compliance(brass_files):
    """The twin with the dashpot effect (the C++ dashpot library) against the full model at
    a dashpot of 0.3 N s/m, the sensors' coupling 0 (Hertz contacts): residuals to 1e-12 and
    every Jacobian column, the dashpot's included, to 1e-8 of its largest."""
    compliant, x = _problem(brass_files, solve=True, plastic=False)
    rigid, _ = _problem(brass_files, plastic=False, compliant_sensors=False, dashpot=True)
    assert rigid.simulates_natively()
    for name, value in (("eta_s", 3e-7), ("dashpot_n_s_m", 0.3), ("preload_n", 0.5), ("preload_seen", 0.5),
                        ("sensor_beta", 0.2), ("sensor_rate", 0.3)):
        x[compliant.labels.index(name)] = value
    _assert_twin_equals(rigid, compliant, x, ("sensor_coupling", "yield_softening"))


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it (test_compliant_sensor holds the sensor kernels to solve)
def test_compliant_sensors_on_the_kernel_equal_solve(brass_files):
    """The full model with compliant sensors (coupling 0.5, f0 = 183 kHz), extra damping, a
    dashpot and a preload half seen, on the C++ kernel's sensor library, against the same
    model on `solve` under `vmap`: residuals to 1e-12 of their largest and every Jacobian
    column to 1e-8 of its largest (measured on the paper's chain with 21 beads: 2e-14, and
    5e-10 for the sensors' rate), the preload's (the sensors' force at rest) included."""
    reference, x = _problem(brass_files, solve=True, plastic=False)
    kernel, _ = _problem(brass_files, plastic=False)
    assert kernel.simulates_natively() and not reference.simulates_natively()
    for name, value in (("eta_s", 3e-7), ("dashpot_n_s_m", 0.3), ("preload_n", 0.5), ("preload_seen", 0.5),
                        ("sensor_beta", 0.2), ("sensor_rate", 0.3), ("sensor_coupling", 0.5)):
        x[reference.labels.index(name)] = value
    # (on Hertz contacts the yield's column is 0 in both; the preload's share seen acts after
    # the simulation, the same arithmetic in both)
    _assert_twin_equals(kernel, reference, x, ("yield_softening",))


def test_evaluator_takes_the_twin_only_where_it_is_exact():
    """Compliance c x rate: a twin where it is 0 and so is its derivative in every column
    asked for (in c: the rate; in the rate: c); the one without the dashpot where the dashpot
    is 0 and its column not asked for, else the one with it; the law's own problem elsewhere."""
    law, elastic, law_twin, elastic_twin, law_dashpot, elastic_dashpot = (object() for _ in range(6))
    evaluate = _Evaluator(law, elastic, plastic_columns=[4], twins={law: law_twin, elastic: elastic_twin},
                          dashpot_twins={law: law_dashpot, elastic: elastic_dashpot},
                          compliance_columns=(0, 1), dashpot_column=5)
    x = np.zeros(6)
    assert evaluate.problem_at(x) is elastic_twin and evaluate.problem_at(x, range(5)) is elastic_twin
    assert evaluate.problem_at(x, [5]) is elastic_dashpot
    x[4] = 1.0  # a yield force: the plastic law
    assert evaluate.problem_at(x, range(5)) is law_twin
    x[1] = 0.3  # a rate, coupling 0: exact unless the coupling's derivative is asked for
    assert evaluate.problem_at(x) is law_twin and evaluate.problem_at(x, [1, 2]) is law_twin
    assert evaluate.problem_at(x, [0]) is law
    x[0], x[1] = 0.5, 0.0  # a coupling, rate 0: exact unless the rate's derivative is asked for
    assert evaluate.problem_at(x, [0, 3]) is law_twin and evaluate.problem_at(x, [1]) is law
    x[1] = 0.3  # both: compliant sensors
    assert evaluate.problem_at(x) is law
    x[5] = 1e-3  # a dashpot, with compliant sensors
    assert evaluate.problem_at(x) is law
    x[0] = 0.0  # a dashpot, rigid sensors
    assert evaluate.problem_at(x) is law_dashpot and evaluate.problem_at(x, [5]) is law_dashpot
    assert evaluate.problem_at(x, [0]) is law


def test_evaluator_residuals_and_predictions_come_from_one_compiled_model(brass_files):
    """The evaluator's residuals, (model - data) / sigma from its model vector, equal the
    problem's own whitened residuals to round-off at several points, its predictions equal
    `Problem.predictions`, and all of them run one compilation of the model vector: the
    residuals, the predictions (`locate`'s windows) and new points reuse it."""
    import jax

    problem, x = _problem(brass_files, plastic=False, compliant_sensors=False, dashpot=False)
    compiled = []

    def listen(event, duration, fun_name=None, **_):
        if event.endswith("backend_compile_duration") and "_model_vector" in str(fun_name):
            compiled.append(fun_name)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        evaluate = _Evaluator(problem)
        points = [x]
        for label, value in (("eta", 1e-6), ("eta_s", 2e-6)):  # the header's damping, the effect's
            points.append(x.copy())
            points[-1][problem.labels.index(label)] = value
        residuals = [evaluate.residuals(p) for p in points]
        predictions = [evaluate.predictions(p) for p in points[:2]]
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    assert len(compiled) == 1, compiled
    data, sigma = problem.data_vector(), problem.sigma_vector()
    assert np.all(np.isfinite(sigma))  # every sample fitted: the model is data + sigma r
    for k, (point, r) in enumerate(zip(points, residuals)):
        reference = np.asarray(problem.residuals(point))
        assert np.max(np.abs(r - reference)) <= 1e-12 * np.max(np.abs(reference))
        if k < len(predictions):
            model = data + sigma * reference
            for predicted, slices in zip(predictions[k], problem.residual_slices()):
                assert predicted.keys() == slices.keys()
                for name, part in slices.items():
                    np.testing.assert_allclose(predicted[name], model[part], rtol=0, atol=1e-9 * np.max(np.abs(model)))
    assert np.max(np.abs(residuals[1] - residuals[0])) > 1e-3 * np.max(np.abs(residuals[0]))  # the points differ
