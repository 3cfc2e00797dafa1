"""The trace-file format: exact example from the specification, round trip, and every error."""

import textwrap

import numpy as np
import pytest

import hertzchain as hc
from hertzchain.tracefile import TraceFile, TraceFileError, read_trace, setup_header, write_trace

EXAMPLE = textwrap.dedent(
    """\
    # format = hertzchain-trace/1
    # n_beads = 21
    # bead_radius_m = 0.013
    # bead_density_kg_m3 = 7780
    # bead_youngs_pa = 2.03e11
    # bead_poisson = 0.3
    # wall_youngs_pa = 2.03e11
    # wall_poisson = 0.3
    # striker_mass_kg = 0.0089
    # striker_velocity_m_s = 0.3
    # noise_std_n = 0.37
    time_s,contact_6,contact_11,wall
    2.0e-06,0.22,0.82,0.37
    4.0e-06,0.25,0.80,0.30
    6.0e-06,0.21,0.79,0.33
    """
)


def _write(tmp_path, text, name="trace.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_the_specification_example_and_builds_its_setup(tmp_path):
    trace = read_trace(_write(tmp_path, EXAMPLE))
    assert trace.channel_names == ("contact_6", "contact_11", "wall")
    assert trace.contacts == (6, 11)
    assert trace.sample_interval_s == pytest.approx(2e-6)
    assert trace.noise_std_n == pytest.approx(0.37)
    np.testing.assert_allclose(trace.channels["contact_11"], [0.82, 0.80, 0.79])
    setup = trace.setup()
    assert setup.n_beads == 21
    assert float(setup.striker_mass_kg) == pytest.approx(0.0089, rel=1e-12)
    # a sphere of the beads' steel: radius 6.49 mm
    assert float(setup.striker_radius_m) == pytest.approx(6.49e-3, rel=2e-3)
    assert float(setup.contact_kappa()[5]) * 1e-9 == pytest.approx(11.99, abs=1e-2)


def test_round_trip_of_a_simulated_run(tmp_path):
    setup = hc.ChainSetup(10, striker_mass_kg=0.02, sensor_beads=(4,))
    run = hc.simulate(setup, t_end_s=0.3e-3, contacts=(2, 7), sample_interval_s=2e-6)
    channels = {name: np.asarray(run.forces_n[name]) for name in run.channel_names}
    original = TraceFile(header=setup_header(setup) | {"x_note": "round trip"}, time_s=np.asarray(run.time_s), channels=channels)
    write_trace(tmp_path / "run.csv", original)
    again = read_trace(tmp_path / "run.csv")
    assert again.header == original.header
    assert again.channel_names == ("contact_2", "contact_7", "sensor_4", "wall")
    for name in channels:
        np.testing.assert_allclose(again.channels[name], channels[name], rtol=1e-8, atol=1e-12 * channels[name].max())
    assert again.setup().sensor_beads == (4,)
    assert float(again.setup().striker_mass_kg) == pytest.approx(0.02, rel=1e-9)


@pytest.mark.parametrize(
    "edit, match",
    [
        (lambda t: t.replace("# n_beads = 21\n", ""), "missing header key '# n_beads"),
        (lambda t: t.replace("# format = hertzchain-trace/1", "# format = other/2"), "format is 'other/2'"),
        (lambda t: t.replace("# noise_std_n", "# noise_sigma"), "unknown header key 'noise_sigma'.*prefix your own keys with 'x_'"),
        (lambda t: t.replace("# bead_radius_m = 0.013", "# bead_radius_m = 13"), "bead_radius_m = 13.0 is outside the plausible range"),
        (lambda t: t.replace("# bead_youngs_pa = 2.03e11", "# bead_youngs_pa = 203"), "bead_youngs_pa = 203.0 is outside"),
        (lambda t: t.replace("# striker_velocity_m_s = 0.3", "# striker_velocity_m_s = -0.3"), "striker_velocity_m_s must be positive and finite .*, got -0.3"),
        (lambda t: t.replace("# bead_poisson = 0.3", "# bead_poisson = abc"), "bead_poisson = 'abc' is not a number"),
        (lambda t: t.replace("contact_11", "contact_25"), "contact_25: contacts run from 0 to 20"),
        (lambda t: t.replace("contact_11", "force_11"), "unknown channel 'force_11'"),
        (lambda t: t.replace("contact_11", "sensor_11"), "sensor_11 needs the header key sensor_beta"),
        (lambda t: t.replace("4.0e-06,0.25", "4.0e-06,nan"), "contact_6 has NaN or inf at sample 2"),
        (lambda t: t.replace("4.0e-06", "1.0e-06"), "time_s is not increasing at row 2"),
        (lambda t: t.replace("6.0e-06", "7.0e-06"), "time_s is not evenly spaced"),
        (lambda t: t.replace("6.0e-06,0.21,0.79,0.33", "6.0e-06,0.21,0.79"), "rows have|columns"),
        (lambda t: t.replace("time_s,", "t,"), "the first column must be time_s"),
        (lambda t: t.split("time_s")[0] + "time_s,wall\n1e-6,0.1\n2e-6,0.2\n", "need at least 3 samples"),
    ],
)
def test_every_malformed_field_is_named(tmp_path, edit, match):
    with pytest.raises(TraceFileError, match=match):
        read_trace(_write(tmp_path, edit(EXAMPLE)))


def test_missing_velocity_must_be_supplied(tmp_path):
    trace = read_trace(_write(tmp_path, EXAMPLE.replace("# striker_velocity_m_s = 0.3\n", "")))
    assert trace.striker_velocity_m_s is None
    with pytest.raises(TraceFileError, match="no striker_velocity_m_s"):
        trace.setup()
    assert float(trace.setup(striker_velocity_m_s=0.25).striker_velocity_m_s) == 0.25


def test_write_is_whole_or_nothing(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("previous")
    bad = TraceFile.__new__(TraceFile)  # bypass validation to force a failure while writing
    object.__setattr__(bad, "header", {"format": "hertzchain-trace/1"})
    object.__setattr__(bad, "time_s", np.arange(3.0))
    object.__setattr__(bad, "channels", {"wall": np.arange(2.0)})
    with pytest.raises(ValueError):
        write_trace(target, bad)
    assert target.read_text() == "previous"
    assert list(tmp_path.iterdir()) == [target]
