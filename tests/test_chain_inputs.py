"""Bad input gets a clear error that names the field; the embedded sensor splits a bead."""

import equinox as eqx
import numpy as np
import pytest

import hertzchain as hc
from hertzchain.chain import build_model


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(bead_radius_m=-0.013), "bead_radius_m must be positive"),
        (dict(bead_radius_m=np.nan), "bead_radius_m contains NaN"),
        (dict(bead_density_kg_m3=0.0), "bead_density_kg_m3 must be positive"),
        (dict(bead_youngs_pa=-2e11), "bead_youngs_pa must be positive"),
        (dict(bead_poisson=0.6), r"bead_poisson must be in \(-1, 0.5\)"),
        (dict(wall_poisson=-1.5), r"wall_poisson must be in \(-1, 0.5\)"),
        (dict(striker_velocity_m_s=np.inf), "striker_velocity_m_s must be positive and finite"),
        (dict(striker_velocity_m_s=-0.3), "striker_velocity_m_s must be positive"),
        (dict(eta_s=-1e-6), "eta_s must be non-negative"),
        (dict(mu=np.nan), "mu contains NaN"),
        (dict(precompression_n=-1.0), "precompression_n must be >= 0"),
        (dict(bead_radius_m=[0.01, 0.02]), "one value per bead"),
        (dict(sensor_beads=(0,)), "sensor_beads: bead 0 is not in the chain"),
        (dict(sensor_beads=(3,), sensor_beta=1.2), r"sensor_beta must be in \(0, 1\)"),
        (dict(striker_mass_kg=0.01, striker_radius_m=0.01), "not both"),
        (dict(end="sticky"), "end must be one of"),
    ],
)
def test_bad_setup_values_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        hc.ChainSetup(**kwargs)


@pytest.mark.parametrize(
    "field, factor, match",
    [
        ("bead_radius_m", -1.0, "a bead or striker mass is not positive and finite"),
        ("bead_youngs_pa", 0.0, "a contact or sensor stiffness is not positive and finite"),
        ("eta_s", np.nan, "eta_s, dashpot_n_s_m, mu, precompression_n or striker_velocity_m_s is not finite"),
    ],
)
def test_bad_traced_values_raise_at_run_time(field, factor, match):
    """Values changed inside a jitted function skip `ChainSetup`'s checks; the solver's
    model checks them (eqx.error_if) instead of returning NaN forces."""
    setup = hc.ChainSetup(4, eta_s=1e-6)
    grid = hc.choose_time_grid(setup, t_end_s=0.2e-3, sample_interval_s=2e-6)

    @eqx.filter_jit
    def wall_force(value):
        changed = eqx.tree_at(lambda s: getattr(s, field), setup, value)
        return hc.solve(changed, grid).forces_n["wall"]

    value = getattr(setup, field)
    assert np.all(np.isfinite(np.asarray(wall_force(value))))
    with pytest.raises(RuntimeError, match=match):
        wall_force(value * factor).block_until_ready()


@pytest.mark.parametrize("n_beads", [0, -3, 2.5])
def test_chain_needs_beads(n_beads):
    with pytest.raises(ValueError, match="n_beads must be a positive integer"):
        hc.ChainSetup(n_beads)


def test_time_step_too_coarse_is_refused_with_the_limit():
    with pytest.raises(ValueError, match=r"dt_s = 1e-05 s cannot resolve the shortest contact .* use dt_s <="):
        hc.simulate(hc.ChainSetup(), dt_s=1e-5, sample_interval_s=1e-5)
    with pytest.raises(ValueError, match="whole multiple of dt_s"):
        hc.simulate(hc.ChainSetup(), dt_s=0.3e-6, sample_interval_s=1e-6)
    with pytest.raises(ValueError, match="t_end_s must be a positive time"):
        hc.simulate(hc.ChainSetup(), t_end_s=-1.0)


def test_unknown_contact_is_refused():
    with pytest.raises(ValueError, match="contact 21 is not in the chain"):
        hc.simulate(hc.ChainSetup(), contacts=(21,))


def test_chosen_step_resolves_the_contact_with_the_documented_margin(paper_setup):
    grid = hc.choose_time_grid(paper_setup, t_end_s=2.5e-3, sample_interval_s=1e-6)
    t_contact = hc.shortest_contact_time_s(paper_setup)
    assert t_contact / grid.dt_s >= 200
    assert grid.sample_interval_s == pytest.approx(1e-6)
    assert grid.n_samples == 2500


def test_sensor_bead_is_two_halves_joined_by_the_eq4_spring():
    setup = hc.ChainSetup(6, sensor_beads=(3,), sensor_beta=0.11, sensor_f0_hz=85e3)
    model = build_model(setup)
    mass = float(setup.bead_mass_kg[2])
    np.testing.assert_allclose(np.asarray(model.mass_kg[3:5]), [0.89 * mass, 0.11 * mass])
    assert float(np.sum(model.mass_kg)) == pytest.approx(float(setup.striker_mass_kg + setup.bead_mass_kg.sum()))
    k_s = float(model.spring_n_m[3])
    omega0 = np.sqrt(k_s * (1 / (0.11 * mass) + 1 / (0.89 * mass)))
    assert omega0 / (2 * np.pi) == pytest.approx(85e3, rel=1e-12)
    # the paper's sensor: k_s = 1.9 kN/um is of the same order (its bead halves are not ours)
    assert 0.3e9 < k_s < 3e9
    run = hc.simulate(setup, t_end_s=0.4e-3, contacts=(2, 3), sample_interval_s=0.5e-6)
    signal = np.asarray(run.forces_n["sensor_3"]).max()
    back, front = (np.asarray(run.forces_n[f"contact_{k}"]).max() for k in (2, 3))
    assert 0.85 * front < signal < 1.0 * max(front, back)
