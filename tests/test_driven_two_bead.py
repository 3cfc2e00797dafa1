"""Two beads with end contacts of their own stiffness: the linear modes against the 2-DOF closed
form, the inverse from two mode frequencies, and a fit factor on some contacts only."""

import math

import jax
import numpy as np
import pytest

from fitting.driven.joint import _leaf, scaled_chain
from hertzchain import laws
from hertzchain.driven import DrivenChain
from hertzchain.driven.linear import normal_modes, symmetric_pair_stiffness_n_m

MASS_KG = 0.028
PRELOAD_N = 3.0


def kappa_for(stiffness_n_m):
    """The Hertz constant with linear stiffness `stiffness_n_m` at `PRELOAD_N` (k = 1.5 kappa^(2/3) F^(1/3))."""
    return (stiffness_n_m / (1.5 * PRELOAD_N ** (1 / 3))) ** 1.5


def chain(face_n_m, middle_n_m, wall_n_m, support_n_m=None):
    support = None if support_n_m is None else laws.IwanSupport(support_n_m, 2e-8)
    return DrivenChain(
        [MASS_KG, MASS_KG],
        [kappa_for(face_n_m), kappa_for(middle_n_m), kappa_for(wall_n_m)],
        PRELOAD_N,
        700.0,
        support_friction=support,
    )


@pytest.mark.parametrize("support_n_m", [None, 2.8e6])
def test_symmetric_modes_match_the_in_phase_and_antiphase_closed_form(support_n_m):
    end, middle = 5.0e6, 1.13e7
    ks = 0.0 if support_n_m is None else support_n_m
    f, shapes = normal_modes(chain(end, middle, end, support_n_m))
    expected = np.sqrt(np.array([end + ks, end + 2 * middle + ks]) / MASS_KG) / (2 * math.pi)
    np.testing.assert_allclose(np.asarray(f), expected, rtol=1e-10)
    # in phase, then antiphase
    assert float(shapes[0, 0] * shapes[1, 0]) > 0 > float(shapes[0, 1] * shapes[1, 1])


def test_asymmetric_modes_match_the_trace_and_determinant():
    k0, k1, k2 = 7.5e5, 9.7e6, 1.245e7
    f = np.asarray(normal_modes(chain(k0, k1, k2))[0])
    trace, det = (k0 + 2 * k1 + k2) / MASS_KG, ((k0 + k1) * (k1 + k2) - k1**2) / MASS_KG**2
    omega2 = (
        np.array([trace - math.sqrt(trace**2 - 4 * det), trace + math.sqrt(trace**2 - 4 * det)]) / 2
    )
    np.testing.assert_allclose(f, np.sqrt(omega2) / (2 * math.pi), rtol=1e-10)


@pytest.mark.parametrize("support_n_m", [None, 2.8e6])
def test_pair_stiffness_inverts_the_normal_modes(support_n_m):
    end, middle = 2.1e6, 1.13e7
    c = chain(end, middle, end, support_n_m)
    f = normal_modes(c)[0]
    got = symmetric_pair_stiffness_n_m(f, MASS_KG, 0.0 if support_n_m is None else support_n_m)
    np.testing.assert_allclose(np.asarray(got), [end, middle], rtol=1e-10)
    np.testing.assert_allclose(
        np.asarray(c.contact_stiffness_n_m()), [end, middle, end], rtol=1e-12
    )


def test_pair_stiffness_of_the_measured_modes():
    # 2120 / 4995 Hz, 28 g: m w1^2 = 4.968e6 N/m, (m w2^2 - m w1^2) / 2 = 1.1306e7 N/m
    end, middle = symmetric_pair_stiffness_n_m([2120.0, 4995.0], MASS_KG)
    assert float(end) == pytest.approx(MASS_KG * (2 * math.pi * 2120.0) ** 2, rel=1e-12)
    assert float(middle) / float(end) == pytest.approx(2.2757, abs=1e-4)


def test_pair_stiffness_names_a_wrong_shape():
    with pytest.raises(ValueError, match="mode_frequencies_hz"):
        symmetric_pair_stiffness_n_m([2120.0, 4995.0, 6000.0], MASS_KG)


def test_factor_on_some_entries_scales_only_those():
    c = chain(5e6, 1.1e7, 5e6)
    scaled = scaled_chain(
        c, ("contact_kappa_n_m1p5[0,2]", "contact_kappa_n_m1p5[1]"), np.array([0.3, -0.2])
    )
    ratio = np.asarray(scaled.contact_kappa_n_m1p5 / c.contact_kappa_n_m1p5)
    np.testing.assert_allclose(ratio, [math.exp(0.3), math.exp(-0.2), math.exp(0.3)], rtol=1e-14)
    np.testing.assert_allclose(
        np.asarray(_leaf(scaled, "contact_kappa_n_m1p5[1]")),
        [float(c.contact_kappa_n_m1p5[1]) * math.exp(-0.2)],
        rtol=1e-14,
    )


def test_end_factor_derivative_of_the_in_phase_mode():
    # f1 = sqrt((k_e + k_s) / m) / 2 pi with k_e ~ kappa^(2/3): d ln f1 / d ln kappa_e = k_e / (3 (k_e + k_s))
    end, ks = 2.1e6, 2.8e6
    c = chain(end, 1.13e7, end, ks)

    def log_f1(x):
        return jax.numpy.log(normal_modes(scaled_chain(c, ("contact_kappa_n_m1p5[0,2]",), x))[0][0])

    derivative = float(jax.grad(log_f1)(jax.numpy.zeros(1))[0])
    assert derivative == pytest.approx(end / (3 * (end + ks)), rel=1e-9)
    h = 1e-5
    difference = (float(log_f1(jax.numpy.array([h]))) - float(log_f1(jax.numpy.array([-h])))) / (
        2 * h
    )
    assert derivative == pytest.approx(difference, rel=1e-7)


def test_bad_entries_name_the_parameter():
    with pytest.raises(ValueError, match=r"contact_kappa_n_m1p5\[a\]"):
        scaled_chain(chain(5e6, 1.1e7, 5e6), ("contact_kappa_n_m1p5[a]",), np.zeros(1))


def test_series_compliance_at_the_ends_only_gives_the_series_formula_modes():
    # Hertz at every contact (sphere-flat ends, sphere-sphere between), the ends in series with a
    # spring of compliance c: k_e = 1 / (1/k_hertz + c), the bead-bead contact plain Hertz
    kappa_flat, kappa_sphere, force, c = 1.38e10, 9.7576e9, 4.5, 1.3e-7
    two = DrivenChain(
        [MASS_KG, MASS_KG],
        [kappa_flat, kappa_sphere, kappa_flat],
        force,
        0.0,
        contact_law=laws.SeriesCompliance(laws.Hertz(), [c, 0.0, c]),
    )
    end = 1.0 / (1.0 / (1.5 * kappa_flat ** (2 / 3) * force ** (1 / 3)) + c)
    middle = 1.5 * kappa_sphere ** (2 / 3) * force ** (1 / 3)
    f = normal_modes(two)[0]
    expected = np.sqrt(np.array([end, end + 2 * middle]) / MASS_KG) / (2 * math.pi)
    np.testing.assert_allclose(np.asarray(f), expected, rtol=1e-10)
    np.testing.assert_allclose(
        np.asarray(symmetric_pair_stiffness_n_m(f, MASS_KG)), [end, middle], rtol=1e-10
    )
