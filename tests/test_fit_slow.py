"""Longer fits: the paper's inverse problem, an unknown wall's modulus."""

import numpy as np
import pytest

import fitting
from fitting.synthetic import paper_setups, synthetic_traces

pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore::fitting.fit.FitWarning")]


def _noisy(setups, contacts, t_end_s, seed):
    clean = synthetic_traces(setups, contacts=contacts, t_end_s=t_end_s)
    sigma = [0.005 * max(np.max(v) for v in f.channels.values()) for f in clean]
    return synthetic_traces(setups, contacts=contacts, t_end_s=t_end_s, noise_std_n=sigma, seed=seed)


def test_unknown_soft_wall_modulus_from_wall_and_incident_traces():
    """A 5 GPa wall (the paper's Fig. 3b) recovered from a start 10 times too stiff."""
    setups = paper_setups([0.2, 0.4], wall_youngs_pa=5e9, wall_poisson=0.3)
    files = _noisy(setups, (11,), 2.5e-3, seed=4)
    result = fitting.fit(files, ("wall_youngs_pa", "eta_s", "mu"), start={"wall_youngs_pa": 5e10},
                         progress=False)
    assert result.converged
    value, error = result.values["wall_youngs"], result.stderr["wall_youngs"]
    assert abs(value - 5e9) < 3 * error
    assert error / 5e9 < 0.01
