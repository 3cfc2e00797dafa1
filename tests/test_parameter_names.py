"""One name per quantity: a fitted parameter is written and shown by its unit-suffixed name
(`eta_s`, `wall_youngs_pa`), the previous short name still read, with a one-line warning."""

import json
import warnings

import numpy as np
import pytest

from fitting.parameters import (
    REGISTRY,
    ParameterNameWarning,
    get_spec,
    parse_parameter_list,
    public_label,
    public_names,
    resolve_label,
    resolve_name,
)
from fitting.priors import PriorError, parse_priors
from fitting.synthetic import synthetic_traces
from hertzchain.chain import ChainSetup
from hertzchain.cli import main
from hertzchain.cli.warning_format import command_warnings
from hertzchain.io.tracefile import write_trace
from hertzchain.parameters import PARAMETERS

WALL_PA = 20e9  # the hidden soft wall of the data below (the beads' header says nothing else)
OLD_NAMES = ("eta", "wall_youngs", "striker_velocity", "precompression", "bead_youngs", "bead_radius",
             "time_offset")


def test_each_setup_parameter_is_named_as_the_setup_field_it_sets():
    # the public name of a fitted setup quantity is the ChainSetup field its setter writes
    fields = {"eta": "eta_s", "mu": "mu", "mu_star": "mu_star", "wall_youngs": "wall_youngs_pa",
              "wall_poisson": "wall_poisson", "precompression": "precompression_n",
              "bead_youngs": "bead_youngs_pa", "bead_radius": "bead_radius_m",
              "striker_velocity": "striker_velocity_m_s"}
    setup = ChainSetup(4)
    for key, field in fields.items():
        assert REGISTRY[key].public_name == field
        changed = PARAMETERS[key].set(setup, 1.5 * float(np.atleast_1d(getattr(setup, field))[0]) + 0.1)
        assert not np.allclose(np.asarray(getattr(changed, field)), np.asarray(getattr(setup, field))), key
    assert REGISTRY["C"].public_name == "C" and REGISTRY["time_offset"].public_name == "time_offset_s"
    assert not set(OLD_NAMES) & set(public_names())


def test_both_spellings_resolve_and_only_the_old_one_warns():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve_name("wall_youngs_pa", where="--params") == "wall_youngs"
        assert resolve_label("striker_velocity_m_s[run1]", where="--fixed") == "striker_velocity[run1]"
        # code holding a key looks it up, without resolving it as a user's spelling
        assert get_spec("wall_youngs") is get_spec("wall_youngs_pa") is REGISTRY["wall_youngs"]
    with pytest.warns(ParameterNameWarning) as caught:
        assert resolve_name("wall_youngs") == "wall_youngs"  # a library call: no option to name
    assert [str(w.message) for w in caught] == [
        ("'wall_youngs' is now called 'wall_youngs_pa'; write wall_youngs_pa (the old name is accepted until the "
         "next release).")]
    with pytest.warns(ParameterNameWarning) as caught:
        assert parse_parameter_list("eta,mu,C", where="--params") == ("eta", "mu", "C")
    assert len(caught) == 1
    message = str(caught[0].message)
    assert message == ("--params: 'eta' is now called 'eta_s'; write eta_s (the old name is accepted until the "
                       "next release).")
    with pytest.warns(ParameterNameWarning, match="'eta' is now called 'eta_s'"):
        assert parse_parameter_list("eta_s,eta,mu") == ("eta", "mu")
    assert public_label("striker_velocity[run1]") == "striker_velocity_m_s[run1]"
    assert public_label("gain[run1:wall]") == "gain[run1:wall]" and public_label("C") == "C"
    with pytest.raises(ValueError, match=r"Unknown parameter 'eta_us' in --params\. Fittable parameters: "
                                         r"eta_s, mu, C, mu_star, wall_youngs_pa"):
        parse_parameter_list("eta_us", where="--params")


def test_a_prior_in_either_spelling_is_the_same_prior_and_twice_is_refused():
    new, = parse_priors(["bead_youngs_pa=203GPa+-4GPa"], source="--prior")
    with pytest.warns(ParameterNameWarning, match="'bead_youngs' is now called 'bead_youngs_pa'"):
        old, = parse_priors(["bead_youngs=203GPa+-4GPa"], source="--prior")
    assert (new.key, new.centre, new.sd) == (old.key, old.centre, old.sd) == ("bead_youngs", 203e9, 4e9)
    with pytest.raises(PriorError, match="two priors for eta_s"), pytest.warns(ParameterNameWarning):
        parse_priors(["eta=0..10us", "eta_s=0..5us"])


@pytest.fixture(scope="module")
def soft_wall_traces(tmp_path_factory):
    """Two shots of a 6-bead chain on a 20 GPa wall (the default beads and striker), 0.3 % noise."""
    folder = tmp_path_factory.mktemp("soft_wall")
    setups = [ChainSetup(6, striker_velocity_m_s=v, eta_s=1e-6, mu=0.0, wall_youngs_pa=WALL_PA) for v in (0.2, 0.4)]
    clean = synthetic_traces(setups, t_end_s=0.25e-3)
    sigma = [0.003 * max(np.max(c) for c in trace.channels.values()) for trace in clean]
    paths = []
    for k, trace in enumerate(synthetic_traces(setups, t_end_s=0.25e-3, noise_std_n=sigma, seed=5)):
        paths.append(tmp_path_factory.getbasetemp() / f"shot{k}.csv")
        write_trace(paths[-1], trace)
    return [str(p) for p in paths], folder


def _fit(paths, out, params, fixed, start):
    return main(["fit", *paths, "--params", params, "--fixed", fixed, "--start", start, "--out", str(out),
                 "--quiet", "--no-plots"])


@pytest.mark.slow  # default-suite time on 2 cores; the spellings' resolution and warnings stay in the default suite
def test_old_and_new_spellings_give_the_same_fit_and_the_report_speaks_the_new(soft_wall_traces, tmp_path, capsys):
    paths, _ = soft_wall_traces
    assert _fit(paths, tmp_path / "new", "wall_youngs_pa,mu", "eta_s=1us", "wall_youngs_pa=60GPa") == 0
    new_out, new_err = capsys.readouterr()
    assert "warning" not in new_err
    with pytest.warns(ParameterNameWarning) as caught:
        assert _fit(paths, tmp_path / "old", "wall_youngs,mu", "eta=1us", "wall_youngs=60GPa") == 0
    capsys.readouterr()
    # one warning per old name, naming the option it was written in; on the terminal one line each
    assert [str(w.message).split(";")[0] for w in caught] == [
        "--params: 'wall_youngs' is now called 'wall_youngs_pa'",
        "--start: 'wall_youngs' is now called 'wall_youngs_pa'", "--fixed: 'eta' is now called 'eta_s'"]
    with command_warnings("fit"):
        line = warnings.formatwarning(caught[2].message, ParameterNameWarning, "fit.py", 1)
    assert line == ("hertzchain fit: warning: --fixed: 'eta' is now called 'eta_s'; write eta_s (the old name is "
                    "accepted until the next release).\n")
    new = json.loads((tmp_path / "new" / "fit.json").read_text())
    old = json.loads((tmp_path / "old" / "fit.json").read_text())
    assert new["params"] == old["params"] and new["chi2"] == old["chi2"]
    assert list(new["params"]) == ["wall_youngs_pa", "mu", "C"] and new["correlation"]["names"] == ["wall_youngs_pa", "mu"]
    wall = new["params"]["wall_youngs_pa"]
    assert new["converged"] and wall["unit"] == "Pa"
    assert abs(wall["value"] - WALL_PA) < 3 * wall["stderr"] and wall["stderr"] < 0.05 * WALL_PA
    assert set(new["starts"][0]["final"]) == {"wall_youngs_pa", "mu"}
    # the terminal and the tables: the new names, the modulus in GPa with its sigma
    line = next(text for text in new_out.splitlines() if text.strip().startswith("wall_youngs_pa = "))
    assert line.strip().endswith("GPa") and " ± " in line
    shown, sigma = (float(part.split()[0]) for part in line.split("=")[1].split("±"))
    assert shown == pytest.approx(wall["value"] / 1e9, rel=0.01) and sigma == pytest.approx(wall["stderr"] / 1e9, rel=0.1)
    table = (tmp_path / "new" / "params.csv").read_text()
    starts = (tmp_path / "new" / "starts.csv").read_text().splitlines()[0]
    assert table.splitlines()[1].startswith("wall_youngs_pa,") and "final_wall_youngs_pa" in starts
    for text in (table, starts, json.dumps(new["params"]), new_out):
        assert "wall_youngs," not in text and "'wall_youngs'" not in text


def test_a_fits_values_read_by_either_spelling():
    """`FitResult.values` and its siblings are keyed in registry spelling; the public name
    (and an instance label in it) reads the same entry, and unknown names still fail."""
    from fitting.parameters import LabelledValues

    values = LabelledValues({"eta": 2e-6, "striker_velocity[run1]": 0.3, "mu": 0.19})
    assert values["eta_s"] == values["eta"] == 2e-6
    assert values["striker_velocity_m_s[run1]"] == 0.3
    assert "wall_youngs_pa" not in values and "eta_s" in values
    assert values.get("precompression_n", "absent") == "absent"
    assert list(values) == ["eta", "striker_velocity[run1]", "mu"]
    with pytest.raises(KeyError):
        values["eta_ms"]


def test_diagnosis_files_name_parameters_as_a_user_writes_them():
    """A diagnosis writes its candidates' and fits' values by the public names
    (`wall_youngs_pa`, `striker_velocity_m_s[shot1]`); effect strengths keep theirs."""
    from fitting.diagnosis.results import CandidateResult, _public_fit

    candidate = CandidateResult(effect="wall_compliance", n_parameters=1, score_chi2=12.0, values={"wall_youngs": 2e10, "wall_softening": 2.3},
                                stderr={"wall_youngs": 1.7e7})
    record = candidate.to_json()
    assert record["values"] == {"wall_youngs_pa": 2e10, "wall_softening": 2.3}
    assert record["stderr"] == {"wall_youngs_pa": 1.7e7}
    summary = _public_fit({"chi2": 10.0, "values": {"striker_velocity[shot1]": 0.3, "eta": 1e-6},
                           "stderr": {"eta": 1e-8}})
    assert summary == {"chi2": 10.0, "values": {"striker_velocity_m_s[shot1]": 0.3, "eta_s": 1e-6},
                       "stderr": {"eta_s": 1e-8}}


def _written_names(text: str) -> set[str]:
    """The previous short names that occur as whole words in `text` (`eta`, not `eta_s`)."""
    import re

    return {name for name in (*OLD_NAMES, "striker_mass", "sensor_f0", "yield_force", "bead_masses")
            if re.search(rf"(?<![\w.]){name}(?![\w])", text)}


def _run_in_both_spellings(tmp_path, capsys, base, public, previous, product):
    """Run the command `base` once with the options `public` (into tmp_path/new) and once with
    `previous` (into tmp_path/old), both writing `<product>.json` and `<product>.csv`; assert
    that both CSVs are the same. Returns the two JSONs, the public run's CSV and console, and
    the first clause of each warning the previous names gave."""
    assert main([*base, *public, "--out", str(tmp_path / "new")]) == 0
    new_out = capsys.readouterr().out
    with pytest.warns(ParameterNameWarning) as caught:
        assert main([*base, *previous, "--out", str(tmp_path / "old")]) == 0
    capsys.readouterr()
    new, old = (json.loads((tmp_path / run / f"{product}.json").read_text()) for run in ("new", "old"))
    table = (tmp_path / "new" / f"{product}.csv").read_text()
    assert table == (tmp_path / "old" / f"{product}.csv").read_text()
    return new, old, table, new_out, [str(w.message).split(";")[0] for w in caught]


@pytest.mark.slow  # default-suite time on 2 cores; the sensitivity boxes' spellings stay in the default suite
def test_sensitivity_reads_either_spelling_gives_the_same_numbers_and_writes_the_public_names(tmp_path, capsys):
    """`hertzchain sensitivity` over a swept grid: the previous names in --params and --sweep
    give the numbers of the public ones, each warns once naming its option, and the JSON,
    the CSV and the console speak only the public names."""
    base = ["sensitivity", "--n-beads", "5", "--eta", "1us", "--mu-star", "0.03", "--observables",
            "wall_peak,contact_2_peak", "--t-end", "0.4ms", "--sample-interval", "2us", "--sweep-velocities", "0.1,0.3"]
    new, old, table, new_out, warned = _run_in_both_spellings(
        tmp_path, capsys, base, ["--params", "eta_s,wall_youngs_pa,mu_star", "--sweep", "eta_s=0.5us,1us"],
        ["--params", "eta,wall_youngs,mu_star", "--sweep", "eta=0.5us,1us"], "sensitivity")
    assert warned == [
        "--params: 'eta' is now called 'eta_s'", "--params: 'wall_youngs' is now called 'wall_youngs_pa'",
        "--sweep: 'eta' is now called 'eta_s'"]
    assert new == old
    assert new["grid"]["axes"] == ["striker_velocity_m_s", "eta_s"]
    assert list(new["params"]) == ["eta_s", "wall_youngs_pa", "mu_star"] and new["params"]["eta_s"]["unit"] == "s"
    assert set(new["elasticity"]["wall_peak"]) == {"eta_s", "wall_youngs_pa", "mu_star"}
    # the peak force grows with the impact velocity as V^(6/5) (dissipation lowers it a little)
    ratio = np.asarray(new["observables"]["wall_peak"]["value"])[1] / np.asarray(new["observables"]["wall_peak"]["value"])[0]
    assert np.all((ratio > 3 ** 1.1) & (ratio < 3 ** 1.2))
    assert table.splitlines()[0].startswith("striker_velocity_m_s,eta_s,observable,")
    assert {row.split(",")[5] for row in table.splitlines()[1:]} == {"eta_s", "wall_youngs_pa", "mu_star"}
    assert "sweep over striker_velocity_m_s (2) x eta_s (2)" in new_out
    for text in (table, json.dumps(new), new_out):
        assert not _written_names(text)


def test_sensitivity_boxes_and_library_calls_read_either_spelling():
    """--box warns once per previous name and yields the same box, by public names; the
    library reads both spellings, a previous one with one warning naming the argument; an
    unknown name lists the public ones."""
    import argparse

    from hertzchain import sensitivity as S
    from hertzchain.cli.sensitivity import _box
    from hertzchain.sensitivity.sweep import check_axes

    new = _box(argparse.Namespace(box=["eta_s=0:2us", "wall_youngs_pa=3GPa:203GPa"]))
    with pytest.warns(ParameterNameWarning) as caught:
        old = _box(argparse.Namespace(box=["eta=0:2us", "wall_youngs=3GPa:203GPa"]))
    assert old == new == {"eta_s": (0.0, 2e-6), "wall_youngs_pa": (3e9, 203e9)}
    assert [str(w.message).split(";")[0] for w in caught] == [
        "--box: 'eta' is now called 'eta_s'", "--box: 'wall_youngs' is now called 'wall_youngs_pa'"]
    with pytest.raises(ValueError, match="--box: eta_s is given twice"), pytest.warns(ParameterNameWarning):
        _box(argparse.Namespace(box=["eta_s=0:2us", "eta=0:1us"]))
    setup = ChainSetup(4, eta_s=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_axes(setup, {"eta_s": [1e-6], "wall_youngs_pa": [5e9]}).keys() == {"eta", "wall_youngs"}
        values = S.parameter_values(setup, ("eta_s", "wall_youngs_pa"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert check_axes(setup, {"eta": [1e-6], "wall_youngs_pa": [5e9]}).keys() == {"eta", "wall_youngs"}
        old = S.parameter_values(setup, ("eta_s", "wall_youngs"))
    assert _first_parts(caught) == [
        "sweep: 'eta' is now called 'eta_s'", "params: 'wall_youngs' is now called 'wall_youngs_pa'"]
    assert float(values["eta_s"]) == float(old["eta_s"]) == 1e-6
    assert float(old["wall_youngs"]) == float(values["wall_youngs_pa"]) == float(setup.wall_youngs_pa)
    with pytest.raises(ValueError, match=r"unknown parameter 'eta_us' in params; valid parameters: eta_s, mu, mu_star, "
                                         r"striker_velocity_m_s, striker_mass_kg"):
        S.sensitivity(setup, ("eta_us",), ("wall_peak",), t_end_s=1e-4)
    with pytest.raises(ValueError, match="a parameter is listed twice: \\('eta_s', 'eta_s'\\)"), \
            pytest.warns(ParameterNameWarning):
        S.sensitivity(setup, ("eta", "eta_s"), ("wall_peak",), t_end_s=1e-4)


def test_each_sensitivity_parameter_is_named_as_the_quantity_it_sets():
    """The public name of a setup parameter is the unit-suffixed `ChainSetup` field (or
    property) it sets: setting it through the registry changes that field and nothing named
    otherwise; the fitted ones agree with `fitting.parameters`."""
    from hertzchain.parameters import public_name

    setup = ChainSetup(4, sensor_beads=(2,), precompression_n=1.0)
    for key, parameter in PARAMETERS.items():
        public = parameter.public_name
        assert public_name(key) == public and (public == key or not public.startswith(key + "_") or parameter.unit)
        if key in REGISTRY:
            assert REGISTRY[key].public_name == public, key
        if key in ("yield_force", "bead_masses"):
            continue  # a contact's yield force, the per-bead masses: no single field
        value = np.asarray(getattr(setup, public))
        changed = parameter.set(setup, 1.25 * parameter.get(setup))
        assert np.allclose(np.asarray(getattr(changed, public)), 1.25 * value, rtol=1e-12), key
    masses = PARAMETERS["bead_masses"].set(setup, 2.0 * setup.bead_mass_kg)
    assert np.allclose(masses.bead_mass_kg, 2.0 * setup.bead_mass_kg) and public_name("bead_masses[3]") == "bead_masses_kg[3]"


@pytest.mark.slow  # default-suite time on 2 cores; the design and diagnose calls' spellings stay in the default suite
def test_design_reads_either_spelling_gives_the_same_numbers_and_writes_the_public_names(tmp_path, capsys):
    """`hertzchain design`: --params and --nuisances by their previous names give the
    numbers of the public ones, each previous name warns once, and design.json, design.csv
    and the console speak only the public names."""
    base = ["design", "--n-beads", "6", "--eta", "1.7us", "--mu", "0.12", "--mu-star", "0.03", "--velocities",
            "0.1,0.3", "--contacts", "2", "--t-end", "0.4ms"]
    new, old, table, new_out, warned = _run_in_both_spellings(
        tmp_path, capsys, base, ["--params", "eta_s,mu,C", "--nuisances", "striker_velocity_m_s"],
        ["--params", "eta,mu,C", "--nuisances", "striker_velocity"], "design")
    assert warned == [
        "--params: 'eta' is now called 'eta_s'", "--nuisances: 'striker_velocity' is now called 'striker_velocity_m_s'"]
    assert {k: v for k, v in new.items() if k != "plan"} == {k: v for k, v in old.items() if k != "plan"}
    assert list(new["params"]) == ["eta_s", "mu", "C"] and new["correlation"]["names"] == ["eta_s", "mu", "C"]
    assert new["nuisances"]["free"] == ["striker_velocity_m_s"]
    assert new["values"] == {"eta_s": pytest.approx(1.7e-6), "mu": 0.12, "mu_star": 0.03}
    eta = new["params"]["eta_s"]
    assert eta["unit"] == "s" and eta["value"] == pytest.approx(1.7e-6) and 0 < eta["relative_stderr"] < 0.1
    assert [row.split(",")[0] for row in table.splitlines()] == ["param", "eta_s", "mu", "C"]
    assert "Fisher information of eta_s, mu, C (free nuisances: striker_velocity_m_s)" in new_out
    for text in (table, json.dumps({k: v for k, v in new.items() if k != "plan"}), new_out):
        assert not _written_names(text)


def test_diagnose_reads_free_parameters_and_nuisances_in_either_spelling():
    """`hertzchain diagnose --free/--nuisances`: both spellings give the same public names,
    which the library takes; a previous name warns once, naming the option; the default
    nuisances are public names."""
    import argparse

    from hertzchain.cli.diagnose import _parameters, add_arguments

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _parameters("eta_s,C", "--free") == ["eta_s", "C"]
        parser = argparse.ArgumentParser()
        add_arguments(parser)
        default = parser.get_default("nuisances")
        assert default == "striker_velocity_m_s,time_offset_s"
        assert _parameters(default, "--nuisances") == ["striker_velocity_m_s", "time_offset_s"]
    with pytest.warns(ParameterNameWarning) as caught:
        assert _parameters("eta,C", "--free") == ["eta_s", "C"]
    assert [str(w.message) for w in caught] == [
        "--free: 'eta' is now called 'eta_s'; write eta_s (the old name is accepted until the next release)."]
    with pytest.raises(ValueError, match="Unknown parameter 'etaa' in --free"):
        _parameters("etaa", "--free")


def test_the_docs_check_resolves_sensitivity_design_and_diagnose_names():
    """`benchmarks/docs_commands.py` holds a documented sensitivity, design or diagnosis to
    the public names: a previous name in a repeatable option (`--sweep`), a nuisance or a
    free parameter is named, the public spelling passes."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import docs_commands

    sweep = ["sensitivity", "--params", "eta_s", "--observables", "wall_peak", "--sweep", "{}=0,1us"]
    assert docs_commands.parse_check([*sweep[:-1], sweep[-1].format("eta_s")]) == (None, None)
    assert docs_commands.parse_check([*sweep[:-1], sweep[-1].format("eta")])[1].startswith(
        "--sweep: 'eta' is now called 'eta_s'")
    design = ["design", "--params", "eta_s,mu,C", "--velocities", "0.1", "--nuisances"]
    assert docs_commands.parse_check([*design, "striker_velocity_m_s,gain"]) == (None, None)
    assert docs_commands.parse_check([*design, "time_offset"])[1].startswith(
        "--nuisances: 'time_offset' is now called 'time_offset_s'")
    assert docs_commands.parse_check(["diagnose", "a.csv", "--free", "wall_youngs"])[1].startswith(
        "--free: 'wall_youngs' is now called 'wall_youngs_pa'")


def test_library_start_values_read_either_spelling_and_an_unknown_key_is_named_publicly(soft_wall_traces):
    """`fitting.fit(start=...)` (`initial_values`) keyed by public names, previous names or
    instance labels gives the same start vector; a key that is not fitted is refused with the
    fitted parameters listed by their public names."""
    from fitting.fit import initial_values, make_problem

    paths, _ = soft_wall_traces
    problem = make_problem(paths, ("eta_s", "wall_youngs_pa", "C"))
    new = initial_values(problem, {"eta_s": 1.3e-6, "wall_youngs_pa": 25e9})
    with pytest.warns(ParameterNameWarning) as caught:
        old = initial_values(problem, {"eta": 1.3e-6, "wall_youngs": 25e9})
    assert _first_parts(caught) == ["start: 'eta' is now called 'eta_s'",
                                    "start: 'wall_youngs' is now called 'wall_youngs_pa'"]
    np.testing.assert_array_equal(new, old)
    assert not np.array_equal(new, initial_values(problem, {"eta_s": 2.6e-6, "wall_youngs_pa": 25e9}))
    with pytest.raises(ValueError, match=r"start: 'mu' is not a fitted parameter; fitted: eta_s, wall_youngs_pa, C\."):
        initial_values(problem, {"mu": 0.1})


def _first_parts(caught) -> list[str]:
    """The warnings' messages up to the name to write ("params: 'eta' is now called 'eta_s'")."""
    return [str(w.message).split(";")[0] for w in caught]


def test_fitting_library_calls_warn_once_per_previous_name_naming_the_argument(soft_wall_traces):
    """`make_problem` (which `fit` and `sample_posterior` build on), `initial_values` and
    `fit(profile=...)`: each previous name warns exactly once, naming the argument it was
    written in, and gives the problem of the public names, which warn nothing."""
    from fitting.fit import fit, initial_values, make_problem

    paths, _ = soft_wall_traces
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = make_problem(paths, ("eta", "wall_youngs_pa", "striker_velocity_m_s"), fixed={"precompression": 0.5},
                           priors=["bead_youngs=203GPa+-4GPa"])
        old_start = initial_values(old, {"wall_youngs": 25e9, "striker_velocity[shot0]": 0.21})
    assert _first_parts(caught) == [
        "priors: 'bead_youngs' is now called 'bead_youngs_pa'", "params: 'eta' is now called 'eta_s'",
        "fixed: 'precompression' is now called 'precompression_n'", "start: 'wall_youngs' is now called 'wall_youngs_pa'",
        "start: 'striker_velocity' is now called 'striker_velocity_m_s'"]
    assert all(w.category is ParameterNameWarning for w in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = make_problem(paths, ("eta_s", "wall_youngs_pa", "striker_velocity_m_s"), fixed={"precompression_n": 0.5},
                           priors=["bead_youngs_pa=203GPa+-4GPa"])
        new_start = initial_values(new, {"wall_youngs_pa": 25e9, "striker_velocity_m_s[shot0]": 0.21})
    assert new.labels == old.labels == ("eta", "wall_youngs", "striker_velocity[shot0]", "striker_velocity[shot1]",
                                        "bead_youngs")
    assert [float(s.precompression_n) for s in new.base_setups] == [float(s.precompression_n) for s in old.base_setups] \
        == [0.5, 0.5]
    np.testing.assert_array_equal(new_start, old_start)
    assert new_start[1] == 25e9 and new_start[2] == 0.21
    with pytest.raises(ValueError, match=r"profile: 'wall_youngs_pa' is not fitted; fitted: eta_s\."), \
            pytest.warns(ParameterNameWarning) as caught:
        fit(paths, ("eta_s",), profile=("wall_youngs",), progress=False)
    assert _first_parts(caught) == ["profile: 'wall_youngs' is now called 'wall_youngs_pa'"]


def test_design_and_diagnose_library_calls_warn_once_per_previous_name(soft_wall_traces):
    """`fitting.design.design` (params, values, nuisances) and `fitting.diagnosis.diagnose`
    (free, nuisances): each previous name warns exactly once, naming its argument; the
    design of the public names warns nothing and gives the same numbers."""
    from fitting.design import design
    from fitting.diagnosis import DiagnosisError, diagnose

    paths, _ = soft_wall_traces
    values = {"eta_s": 1e-6, "wall_youngs_pa": WALL_PA}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        new = design(paths, ("eta_s", "wall_youngs_pa"), values=values, nuisances=("striker_velocity_m_s",))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = design(paths, ("eta", "wall_youngs_pa"), values={"eta": 1e-6, "wall_youngs": WALL_PA},
                     nuisances=("striker_velocity",))
    assert _first_parts(caught) == [
        "params: 'eta' is now called 'eta_s'", "nuisances: 'striker_velocity' is now called 'striker_velocity_m_s'",
        "values: 'eta' is now called 'eta_s'", "values: 'wall_youngs' is now called 'wall_youngs_pa'"]
    assert new.to_json()["params"] == old.to_json()["params"]
    assert 0 < new.relative_stderr["eta_s"] < 1
    with pytest.raises(DiagnosisError, match="nuisances: eta_s is a global parameter"), \
            warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        diagnose(paths, free=("wall_youngs",), nuisances=("eta",), progress=False)
    assert _first_parts(caught) == ["nuisances: 'eta' is now called 'eta_s'",
                                    "free: 'wall_youngs' is now called 'wall_youngs_pa'"]


@pytest.mark.slow  # default-suite time on 2 cores; the fitting calls' warnings stay in the default suite
def test_sensitivity_library_calls_warn_once_per_previous_name_naming_the_argument():
    """`sensitivity`, `sensitivity_sweep` and `global_sensitivity`: a previous name in
    `params`, `sweep` or `box` warns exactly once, naming the argument, and gives the numbers
    of the public name, which warns nothing."""
    from hertzchain import sensitivity as S

    setup = ChainSetup(4, eta_s=1e-6)
    run = {"t_end_s": 0.4e-3, "sample_interval_s": 2e-6}

    def three_calls(eta: str, striker_velocity: str):
        """`sensitivity`, `sensitivity_sweep` and `global_sensitivity` naming eta and the
        striker's velocity `eta` and `striker_velocity`."""
        return (S.sensitivity(setup, (eta, "wall_youngs_pa"), ("wall_peak",), **run),
                S.sensitivity_sweep(setup, ("eta_s",), ("wall_peak",), {striker_velocity: [0.1, 0.2]},
                                    progress=False, **run),
                S.global_sensitivity(setup, ("wall_peak",), {eta: (0.5e-6, 1e-6)}, n_samples=2,
                                     progress=False, **run))

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        local, swept, box = three_calls("eta_s", "striker_velocity_m_s")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        local_old, swept_old, box_old = three_calls("eta", "striker_velocity")
    assert _first_parts(caught) == ["params: 'eta' is now called 'eta_s'",
                                    "sweep: 'striker_velocity' is now called 'striker_velocity_m_s'",
                                    "box: 'eta' is now called 'eta_s'"]
    # each attributed to the call that wrote the old name, in this file
    assert {w.filename for w in caught} == {__file__}
    assert local.params == local_old.params == ("eta_s", "wall_youngs_pa")
    assert local.to_json() == local_old.to_json() and swept.to_json() == swept_old.to_json()
    assert box.to_json() == box_old.to_json() and box.ranking == {"wall_peak": ["eta_s"]}
    with pytest.warns(ParameterNameWarning, match="values: 'eta' is now called 'eta_s'"):
        changed = S.with_parameters(setup, {"eta": 2e-6})
    assert float(changed.eta_s) == 2e-6
