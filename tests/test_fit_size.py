"""`hertzchain fit` refuses, before its first simulation, a fit one iteration of which this
machine cannot hold or would take beyond the bead-step limit (as `synth` and `sweep` do)."""

import re

import pytest

from fitting.data import load_experiments
from fitting.synthetic import synthetic_traces
from hertzchain.chain import ChainSetup
from hertzchain.cli import main
from hertzchain.cli.fit import check_fit_size
from hertzchain.io.tracefile import write_trace
from hertzchain.validation import MAX_BODY_STEPS


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    path = tmp_path_factory.mktemp("shot") / "shot.csv"
    write_trace(path, synthetic_traces([ChainSetup(5, striker_velocity_m_s=0.3)], t_end_s=0.2e-3)[0])
    return str(path)


STEPS_MESSAGE = (r"one iteration of this fit takes [0-9.e+]+ bead-steps \(steps x beads x runs\), above the limit "
                 r"of 1e\+10: fit fewer files or parameters, lower --steps-per-contact or --multistart, or add "
                 r"--yes to run it anyway\.")
MEMORY_MESSAGE = (r"one iteration of this fit needs about [0-9.e+]+ GiB for its recorded samples, more than the "
                  r"[0-9.e+]+ GiB available: fit fewer files, --channels or a smaller --multistart, or add --yes\.")


@pytest.mark.parametrize("option, value, message", [
    # 1e9 steps per contact: 2.5e6 times the default's 400, past 1e10 bead-steps
    ("--steps-per-contact", "1000000000", STEPS_MESSAGE),
    # 1e8 starts at once: their recorded channels and derivatives need terabytes
    ("--multistart", "100000000", MEMORY_MESSAGE),
])
def test_a_fit_too_large_for_the_machine_is_refused_before_it_starts(shot, tmp_path, capsys, option, value, message):
    # the guard itself first, so that a setting it would let through is never run here
    settings = {"multistart": 1, "steps_per_contact": 400, option.lstrip("-").replace("-", "_"): int(value)}
    with pytest.raises(ValueError, match=message):
        check_fit_size(load_experiments([shot]), 1, **settings)
    out = tmp_path / "fit"
    assert main(["fit", shot, "--params", "eta_s", option, value, "--out", str(out), "--quiet"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert error.startswith("hertzchain fit: error: ")
    assert re.search(message, error), error
    assert not out.exists()


def test_an_ordinary_fit_passes_and_the_memory_is_the_machines(shot):
    experiments = load_experiments([shot])
    check_fit_size(experiments, 3, multistart=4, steps_per_contact=400)  # passes: nothing raised
    # 0.2 ms at 1 us: 200 samples x 3 channels x 4 (model and 3 derivatives) x 8 bytes x 3 copies > 1000 bytes
    with pytest.raises(ValueError, match=r"needs about [0-9.e-]+ GiB .* more than the 9\.31e-07 GiB available"):
        check_fit_size(experiments, 3, multistart=1, steps_per_contact=400, memory_bytes=1000)
    with pytest.raises(ValueError, match=re.escape(f"above the limit of {MAX_BODY_STEPS:.0e}")):
        check_fit_size(experiments, 3, multistart=1, steps_per_contact=10**9)
