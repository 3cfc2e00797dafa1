"""Reported values in physical units, to the digits their standard errors allow."""

import math
import types

import pytest

from fitting.diagnosis.report import physical_reading
from fitting.report import summary_text
from hertzchain.chain import ChainSetup
from hertzchain.units import counted, display_unit, format_measured


@pytest.mark.parametrize("value, sigma, unit, text", [
    (2.0312e10, 1.234e9, "Pa", "20.3 ± 1.2 GPa"),
    (6.04e8, 2.1e7, "Pa", "604 ± 21 MPa"),
    (2.0e-6, 1.3e-7, "s", "2.00 ± 0.13 µs"),
    (0.01234, 0.00311, "", "0.0123 ± 0.0031"),
    (0.29871, 0.00042, "m/s", "0.29871 ± 0.00042 m/s"),
    (1234.5, 56.0, "N s/m", "1234 ± 56 N s/m"),
])
def test_value_given_to_the_digits_of_its_error(value, sigma, unit, text):
    assert format_measured(value, sigma, unit) == text


def test_a_count_reads_right_for_one_and_for_many():
    assert [counted(n, "chunk") for n in (0, 1, 2)] == ["0 chunks", "1 chunk", "2 chunks"]
    assert counted(1, "CSV file") == "1 CSV file" and counted(3, "CSV file") == "3 CSV files"
    assert counted(1, "library", "libraries") == "1 library" and counted(4, "library", "libraries") == "4 libraries"


def test_an_undetermined_error_says_so_and_why():
    assert format_measured(0.123456789, math.nan, "", why="no covariance") == "0.1235 (σ not determined: no covariance)"
    assert format_measured(3e9, math.inf, "Pa") == "3 GPa (σ not determined)"
    assert format_measured(3e9, None, "Pa") == "3 GPa (σ not determined)"


def test_units_in_human_text():
    assert display_unit("us") == "µs" and display_unit("1") == "dimensionless" and display_unit("") == "dimensionless"
    assert display_unit("m/s N^-1/6") == "m/s N^-1/6"


def test_effect_strengths_read_as_the_quantities_they_stand_for():
    setup = ChainSetup(5, wall_youngs_pa=203e9, bead_yield_stress_pa=2e9)
    # wall_softening w: Y_w = Y_header exp(-w); sigma_Y = Y_w sigma_w
    assert physical_reading("dx_wall_softening", math.log(203 / 20), 0.05, setup) == \
        "wall Young's modulus 20.0 ± 1.0 GPa"
    # yield_softening s: sigma_Y = sigma_Y0 / s; its error sigma_Y0 sigma_s / s^2
    assert physical_reading("yield_softening", 4.0, 0.2, setup) == "yield stress 500 ± 25 MPa"
    assert physical_reading("eta_s", 1.02e-6, 4.4e-8, setup) == "η 1.020 ± 0.044 µs"
    assert physical_reading("mu", 0.1, 0.01, setup) == "track friction μ 0.100 ± 0.010"
    assert physical_reading("sensor_beta", 0.1, 0.01, setup) == ""  # no quantity of its own


def test_the_fit_summary_prints_significant_digits_and_no_nan():
    result = types.SimpleNamespace(
        converged=True, n_steps=7, reduced_chi2=1.0123456, covariance_scale="noise",
        labels=("eta", "wall_youngs", "striker_velocity[shot1]"),
        values={"eta": 2.00012345e-6, "wall_youngs": 2.0312345e10, "striker_velocity[shot1]": 0.3001234567},
        stderr={"eta": 1.31e-8, "wall_youngs": math.inf, "striker_velocity[shot1]": math.nan},
        units={"eta": "s", "wall_youngs": "Pa", "striker_velocity[shot1]": "m/s"},
        speed_constant={"C": 301.23456, "C_stderr": 0.4567, "C_continuum": 302.5, "mu_star": 0.0},
        warnings=[],
    )
    lines = summary_text(result).splitlines()
    assert lines[1] == "  eta_s = 2.000 ± 0.013 µs"
    assert lines[2] == "  wall_youngs_pa = 20.31 GPa (σ not determined: the data do not determine it)"
    assert lines[3] == ("  striker_velocity_m_s[shot1] = 0.3001 m/s "
                        "(σ not determined: the covariance is not finite at this optimum)")
    assert lines[4] == "  C (discrete solitary wave) = 301.23 ± 0.46 m/s N^-1/6"
    assert "nan" not in summary_text(result) and "+-" not in summary_text(result)


def test_the_diagnosis_reads_a_named_soft_wall_in_gpa():
    from fitting.diagnosis.report import readings

    setup = ChainSetup(5, wall_youngs_pa=203e9)
    step = types.SimpleNamespace(effect="wall_compliance", values={"wall_softening": math.log(203 / 20.3)},
                                 stderr={"wall_softening": 0.0123})
    diagnosis = types.SimpleNamespace(steps=[step], missing_effects=["wall_compliance"], final={},
                                      problem=types.SimpleNamespace(base_setups=[setup]))
    assert readings(diagnosis) == ["wall_compliance: wall Young's modulus 20.30 ± 0.25 GPa"]


def test_the_diagnosis_reads_each_named_strength_at_the_final_fit():
    """A strength refitted after later effects joined the model is read at the final fit
    (where every named effect is in), not at the step that named it."""
    from fitting.diagnosis.report import readings

    steps = [types.SimpleNamespace(effect="viscous_damping", values={"dx_eta_s": 2.0426e-6},
                                   stderr={"dx_eta_s": 5.0e-9}),
             types.SimpleNamespace(effect="track_friction", values={"dx_mu": 0.19}, stderr={"dx_mu": 0.002})]
    final = {"values": {"dx_eta_s": 2.0023e-6, "dx_mu": 0.18982}, "stderr": {"dx_eta_s": 2.2e-9, "dx_mu": 8.0e-4}}
    diagnosis = types.SimpleNamespace(steps=steps, missing_effects=["viscous_damping", "track_friction"],
                                      final=final, problem=types.SimpleNamespace(base_setups=[ChainSetup(5)]))
    assert readings(diagnosis) == ["viscous_damping: η 2.0023 ± 0.0022 µs",
                                   "track_friction: track friction μ 0.18982 ± 0.00080"]


def test_table_columns_state_their_units():
    from hertzchain.units import column_name

    assert column_name("eta", "s") == "eta_s" and column_name("wall_youngs", "Pa") == "wall_youngs_pa"
    assert column_name("striker_velocity[shot1]", "m/s") == "striker_velocity_m_s[shot1]"
    assert column_name("mu", "") == "mu" and column_name("C", "m/s N^-1/6") == "C (m/s N^-1/6)"
