"""The measures of `benchmarks/contact_misfit.py` and `benchmarks/contact_processing.py` on
sequences whose answers are known in closed form, and the record matching on one measured
curve when the data are present."""

import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.contact_misfit import monotone_floor, phases, quartic_floor, residual_overlap_fraction
from benchmarks.contact_processing import best_alignment
from fitting.contact_calibration import read_curve
from hertzchain.materials import STEEL_440C


def test_monotone_floor_is_the_misfit_of_the_best_non_decreasing_force():
    # the approach grows throughout: the force may not fall; best fit 0, 1, 2, 2, 2, 2
    approach = np.linspace(0.0, 1.0, 6)
    force = np.array([0.0, 1.0, 2.0, 3.0, 2.0, 1.0])
    assert monotone_floor(approach, force, 3.0) == pytest.approx(math.sqrt(2 / 6) / 3, rel=1e-12)
    # where the approach falls back, a law may unload: nothing is left
    approach = np.array([0.0, 0.2, 0.4, 0.6, 0.5, 0.4])
    assert monotone_floor(approach, force, 3.0) == 0.0


def test_quartic_floor_vanishes_on_quartics_and_measures_added_ringing():
    time = np.linspace(0.0, 1e-4, 1001)
    smooth = 1e3 * (1 - ((time - 5e-5) / 5e-5) ** 2) ** 2  # a quartic in time, peak 1 kN at 50 us
    assert quartic_floor(time, smooth, 500, 1e3) < 1e-9
    ringing = 20.0 * np.sin(2 * np.pi * time / 2e-6)  # 2 us period: no quartic follows it
    assert quartic_floor(time, smooth + ringing, 500, 1e3) == pytest.approx(20.0 / math.sqrt(2) / 1e3, rel=0.02)


def test_phases_and_residual_overlap_of_a_load_unload_record():
    force = np.array([0.0, 0.1, 0.5, 0.8, 1.0, 0.95, 0.7, 0.5, 0.3, 0.15, 0.05, 0.0])
    approach = np.array([0.0, 0.2, 0.5, 0.8, 0.97, 1.0, 0.95, 0.9, 0.85, 0.82, 0.8, 0.79])
    assert list(phases(force, force)) == ["toe", "toe", "rise", "rise", "top", "top", "fall", "fall", "fall",
                                          "tail", "tail", "tail"]
    # the force first falls below 10 % of its peak at 0.05, where the approach is 0.8 of its largest
    assert residual_overlap_fraction(approach, force, 4, 1.0) == pytest.approx(0.8, rel=1e-12)
    assert residual_overlap_fraction(approach[:-2], force[:-2], 4, 1.0) is None


def test_best_alignment_recovers_a_shift_and_a_scale():
    rng = np.random.default_rng(3)
    record = np.convolve(rng.normal(size=600), np.ones(15) / 15, mode="same") + np.sin(np.linspace(0, 3, 600))
    curve = 0.5 * record[40:540]
    deviation, scale, lag = best_alignment(curve, record)
    assert lag == 40 and scale == pytest.approx(0.5, rel=1e-12) and deviation < 1e-12


DATA = Path(__file__).resolve().parents[2] / "shared/data/real/burgoyne-2014"


@pytest.mark.skipif(not DATA.is_dir(), reason="Burgoyne & Daraio data folder absent")
def test_force15_is_the_july_reprocessing_halved_in_force_and_approach():
    """The paper's `force15` against the stored July reprocessing of the same shot (5-22,
    sample 3): one factor 0.5 on both axes (benchmarks/results/contact_burgoyne/processing.md)."""
    curve = read_curve(DATA / "ExperimentalData" / "force15.mat", STEEL_440C)
    record = read_curve(DATA / "hopkinson_tests_5-22" / "fd_s440-3.mat", STEEL_440C)
    deviation, scale, lag = best_alignment(curve.force_n, record.force_n)
    assert deviation < 0.01 and scale == pytest.approx(0.5, abs=0.002)
    start, other = max(0, -lag), max(0, lag)
    size = min(curve.force_n.size - start, record.force_n.size - other)
    slope, intercept = np.polyfit(record.approach_m[other:other + size], curve.approach_m[start:start + size], 1)
    assert slope == pytest.approx(0.5, abs=0.005)
    residual = curve.approach_m[start:start + size] - slope * record.approach_m[other:other + size] - intercept
    assert np.sqrt(np.mean(residual**2)) < 3e-6  # m: 1.9 um; the 50-ns curves, whose records are not stored, leave 20-25 um
