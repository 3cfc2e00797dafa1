"""The command line in a lab's terms: materials by name, units everywhere, a setup file."""

import argparse
import json
import math

import numpy as np
import pytest

from hertzchain.cli import main
from hertzchain.cli.setup_options import add_setup_arguments, chain_from_args
from hertzchain.io.tracefile import read_trace
from hertzchain.sweep import parse_grid
from hertzchain.units import parse_quantity


def _chain(*options):
    parser = argparse.ArgumentParser()
    add_setup_arguments(parser)
    return chain_from_args(parser.parse_args(list(options)))


def _hertz_kappa(radius_a, youngs_a, poisson_a, radius_b, youngs_b, poisson_b):
    """kappa = (4/3) E* sqrt(R*) of two spheres (Hertz; Johnson, Contact Mechanics, eq. 4.22)."""
    effective_youngs = 1.0 / ((1 - poisson_a**2) / youngs_a + (1 - poisson_b**2) / youngs_b)
    effective_radius = radius_a * radius_b / (radius_a + radius_b)
    return 4.0 / 3.0 * effective_youngs * math.sqrt(effective_radius)


def test_steel_striker_on_brass_beads_against_a_soft_wall(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", "--n-beads", "15", "--bead-material", "brass", "--bead-radius", "5mm",
                 "--striker-material", "steel", "--striker-radius", "3mm", "--wall-youngs", "5GPa",
                 "--t-end", "0.2ms", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "beads: brass" in printed and "striker: bead_steel" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["materials"] == {"bead": "brass", "striker": "bead_steel"}
    assert summary["setup_sources"]["striker_youngs_pa"] == "--striker-material steel"
    assert summary["setup_sources"]["wall_youngs_pa"] == "--wall-youngs"
    # brass 110 GPa, nu 0.34; the bearing steel 203 GPa, nu 0.3 (hertzchain.materials)
    kappa = summary["kappa_n_per_m1p5"]["contacts"]
    assert kappa[0] == pytest.approx(_hertz_kappa(3e-3, 203e9, 0.3, 5e-3, 110e9, 0.34), rel=1e-12)
    assert kappa[1] == pytest.approx(_hertz_kappa(5e-3, 110e9, 0.34, 5e-3, 110e9, 0.34), rel=1e-12)
    header = read_trace(out / "traces.csv").header
    assert header["striker_mass_kg"] == pytest.approx(4 / 3 * math.pi * 7780 * 3e-3**3, rel=1e-12)
    assert header["wall_youngs_pa"] == 5e9 and header["bead_density_kg_m3"] == 8500


def test_an_invented_material_is_refused_with_the_known_ones(tmp_path, capsys):
    assert main(["simulate", "--striker-material", "unobtainium", "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert "--striker-material: Unknown material 'unobtainium'; known materials: bead_steel" in error
    assert "brass" in error and "steel = bead_steel" in error
    assert not list(tmp_path.iterdir())


def test_striker_mass_and_radius_accepted_when_they_agree_refused_naming_both_when_not():
    mass = 4 / 3 * math.pi * 7780 * 0.004**3  # a steel sphere of radius 4 mm: 2.086 g
    chain = _chain("--striker-radius", "4mm", "--striker-mass", f"{mass * 1e3 * 1.002:.6f}g")
    assert float(chain.setup.striker_radius_m) == pytest.approx(0.004, rel=1e-12)
    with pytest.raises(ValueError, match=r"striker mass 0\.0025 kg \(--striker-mass\) and radius 0\.004 m "
                                         r"\(--striker-radius\) disagree.*weighs 0\.002086 kg"):
        _chain("--striker-radius", "4mm", "--striker-mass", "2.5g")
    # with another density, the same pair agrees
    dense = _chain("--striker-radius", "4mm", "--striker-mass", "2.5g", "--striker-density", f"{7780 * 2.5e-3 / mass}")
    assert float(dense.setup.striker_mass_kg) == pytest.approx(2.5e-3, rel=1e-9)


def test_a_setup_file_with_an_override_on_the_command_line(tmp_path):
    config = tmp_path / "setup.toml"
    config.write_text('[chain]\nn_beads = 9\nbead_radius_m = "9.5mm"\nbead_mass_kg = 0.0280\n'
                      'wall_youngs_pa = "45GPa"\nstriker_mass_kg = "16.2g"\n')
    chain = _chain("--config", str(config), "--wall-youngs", "3GPa", "--striker-velocity", "0.2m/s")
    setup = chain.setup
    assert setup.n_beads == 9
    assert float(setup.bead_radius_m[0]) == pytest.approx(9.5e-3)
    assert float(setup.bead_density_kg_m3[0]) == pytest.approx(0.028 / (4 / 3 * math.pi * 9.5e-3**3))
    assert float(setup.wall_youngs_pa) == 3e9 and float(setup.striker_velocity_m_s) == 0.2
    assert float(setup.striker_mass_kg) == pytest.approx(16.2e-3)
    assert chain.sources == {
        "n_beads": str(config), "bead_radius_m": str(config), "bead_density_kg_m3": str(config),
        "wall_youngs_pa": "--wall-youngs", "striker_mass_kg": str(config),
        "striker_velocity_m_s": "--striker-velocity",
    }
    assert "  from --wall-youngs: wall_youngs_pa" in chain.describe()
    config.write_text("[chain]\nbead_radius = 0.01\n")
    with pytest.raises(ValueError, match="unknown key 'bead_radius'; valid keys: n_beads, bead_radius_m"):
        _chain("--config", str(config))


def test_grids_take_unit_suffixes():
    assert parse_grid("wall_youngs_pa=3GPa")[1].tolist() == [3e9]
    np.testing.assert_allclose(parse_grid("eta_s=0:3us:4")[1], [0.0, 1e-6, 2e-6, 3e-6], rtol=1e-12)
    np.testing.assert_allclose(parse_grid("striker_velocity_m_s=10cm/s:1m/s:2:log")[1], [0.1, 1.0])
    with pytest.raises(ValueError, match=r"--grid eta_s: unit 'GPa' in '2GPa' is not a prefixed 's'"):
        parse_grid("eta_s=0,2GPa")


def test_masses_in_grams():
    assert parse_quantity("8.9g", "kg") == pytest.approx(8.9e-3)
    assert parse_quantity("880mg", "kg") == pytest.approx(8.8e-4)
    assert parse_quantity("2kg", "kg") == 2.0


def test_warnings_read_in_the_commands_terms():
    import warnings

    from hertzchain.cli.warning_format import command_warnings
    from hertzchain.integrate import YieldWarning

    warning = YieldWarning("The force at contact 0 reached 9 N, above its yield force 4 N (mean contact "
                           "pressure above bead_yield_stress_pa).",
                           "Lower striker_velocity_m_s, model it with plasticity=True, or set on_yield='ignore'.")
    with command_warnings("simulate"):
        line = warnings.formatwarning(warning, YieldWarning, "integrate.py", 1)
    assert line == ("hertzchain simulate: warning: The force at contact 0 reached 9 N, above its yield force "
                    "4 N (mean contact pressure above --bead-yield-stress). Lower --striker-velocity, or "
                    "model the yield with --plasticity thornton (or jackson_green).\n")
    with command_warnings("fit"):
        line = warnings.formatwarning(UserWarning("a\n  two-line text"), UserWarning, "fit.py", 1)
        with pytest.warns(YieldWarning, match="on_yield='ignore'"):  # the API's warning as it was
            warnings.warn(warning, stacklevel=1)
    assert line == "hertzchain fit: warning: a two-line text\n"
    assert warnings.formatwarning(warning, YieldWarning, "x.py", 1).startswith("x.py:1: YieldWarning")


def test_sensitivity_sweeps_and_boxes_take_unit_suffixes():
    from hertzchain.cli.sensitivity import _box, _sweep_axes

    args = argparse.Namespace(sweep_velocities="10cm/s,0.3", sweep_wall_youngs="3GPa", sweep=["eta_s=0,1us"],
                              box=["eta_s=0:2us", "wall_youngs_pa=3GPa:203GPa"])
    assert _sweep_axes(args) == {"striker_velocity_m_s": [0.1, 0.3], "wall_youngs_pa": [3e9], "eta_s": [0.0, 1e-6]}
    assert _box(args) == {"eta_s": (0.0, 2e-6), "wall_youngs_pa": (3e9, 203e9)}
    with pytest.raises(ValueError, match="--box eta_s: unit 'GPa'"):
        _box(argparse.Namespace(box=["eta_s=0:2GPa"]))
