"""The diagnosis on records of a second code path (`benchmarks/diagnosis_second_path.py`): a soft
wall simulated by the diffrax reference, Thornton plasticity by a NumPy Verlet chain while the
candidate is Jackson & Green's law. The generator's contact law is checked here against the
library's Thornton law (cheap); the diagnoses are slow."""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from hertzchain import contact

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import diagnosis_second_path as second


def test_the_generators_thornton_law_is_the_librarys():
    """The NumPy generator's contact force along a history that loads past yield, unloads,
    separates, reloads below and then beyond the earlier largest overlap equals
    `hertzchain.contact.thornton_contact` (written apart) to round-off; below the yield
    overlap both are Hertz."""
    kappa, yield_force = 4.1e9, 55.0
    yield_overlap = (yield_force / kappa) ** (2 / 3)
    t = np.linspace(0.0, 1.0, 4001)
    overlap = yield_overlap * (3.0 * np.sin(2 * np.pi * t) ** 2 * (1 + t) - 0.5)
    largest = np.maximum.accumulate(np.maximum(overlap, 0.0))
    ours = second._thornton(overlap, largest, kappa, yield_force)
    theirs = np.asarray(contact.thornton_contact(np.maximum(overlap, 0.0), largest, kappa, yield_force)[0])
    assert np.max(largest) > 4 * yield_overlap and np.sum(ours == 0.0) > 100  # yields and separates
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12 * yield_force)
    elastic = overlap < yield_overlap
    below = elastic & (largest < yield_overlap)
    np.testing.assert_allclose(ours[below], kappa * np.maximum(overlap[below], 0) ** 1.5, rtol=1e-12, atol=1e-9)


@pytest.mark.slow
def test_the_numpy_chain_without_yield_is_the_diffrax_reference():
    """The NumPy generator with an infinite yield force against `hertzchain.reference` on the
    brass chain's fastest shot: every recorded channel to 1e-5 of its peak."""
    assert second.elastic_check() < 1e-5


@pytest.mark.slow
def test_a_soft_wall_of_the_diffrax_reference_is_named_with_its_modulus():
    """The brass chain with a 20 GPa wall (the header says 110 GPa), simulated by the diffrax
    reference: `wall_compliance` named, the modulus within 4 standard errors and 2 % of 20 GPa,
    stated in GPa in the conclusion, no alarm, every fit converged."""
    from fitting.diagnosis import diagnose

    files = second.hidden_records(second.SETUP, ("wall_compliance",), code_path="diffrax")
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == ["wall_compliance"]
    assert not diagnosis.misspecification and diagnosis.converged
    softening, error = diagnosis.final["values"]["wall_softening"], diagnosis.final["stderr"]["wall_softening"]
    wall_gpa = 110.0 * math.exp(-softening)
    assert abs(wall_gpa - 20.0) < 4 * wall_gpa * error and abs(wall_gpa / 20.0 - 1) < 0.02
    stated = re.search(r"wall Young's modulus ([0-9.]+) ± ([0-9.]+) GPa \(header 110 GPa\)", diagnosis.conclusion)
    assert stated, diagnosis.conclusion
    assert abs(float(stated.group(1)) - wall_gpa) <= float(stated.group(2))


@pytest.mark.slow
def test_thornton_plasticity_is_named_by_the_jackson_green_candidate():
    """Contacts yielding by Thornton's law (NumPy Verlet) while the library's candidate is
    Jackson & Green's: the effect is what is missing, `plasticity` is named."""
    from fitting.diagnosis import diagnose

    files, _ = second.thornton_records()
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == ["plasticity"]


@pytest.mark.filterwarnings("ignore::hertzchain.integrate.YieldWarning")
def test_a_soft_wall_of_the_diffrax_reference_is_named_on_a_short_chain():
    """The default suite's check of the second code path (the 15-bead cases above are slow): a
    6-bead brass chain with a 20 GPa wall (the header says 110 GPa), three shots simulated by
    the diffrax reference and acquired as the benchmark's records (0.5 % noise, 11 bits, piezo
    channels): `wall_compliance` named alone, the modulus within 4 standard errors and 3 % of
    20 GPa, no alarm, every fit converged."""
    import hertzchain as hc
    from fitting.diagnosis import diagnose
    from hertzchain.reference import simulate_reference

    spec = {"n_beads": 6, "velocities_m_s": (0.1, 0.3, 0.8), "fields": second.SETUPS["brass"]["fields"]}
    runs = []
    for velocity in spec["velocities_m_s"]:
        truth = hc.ChainSetup(6, striker_velocity_m_s=velocity, wall_youngs_pa=20e9, **spec["fields"])
        run = simulate_reference(truth, t_end_s=3.5e-4, sample_interval_s=0.25e-6, contacts=(2, 4), rtol=1e-9)
        runs.append((np.asarray(run.time_s), {name: np.asarray(run.forces_n[name])
                                              for name in ("contact_2", "contact_4", "wall")}))
    files = second.records(runs, spec, "wall_compliance", seed=3, code_path="diffrax")
    diagnosis = diagnose(files, progress=False)
    assert diagnosis.missing_effects == ["wall_compliance"]
    assert not diagnosis.misspecification and diagnosis.converged
    softening, error = diagnosis.final["values"]["wall_softening"], diagnosis.final["stderr"]["wall_softening"]
    wall_gpa = float(files[0].header["wall_youngs_pa"]) / 1e9 * math.exp(-softening)
    assert abs(wall_gpa - 20.0) < 4 * wall_gpa * error and abs(wall_gpa / 20.0 - 1) < 0.03
