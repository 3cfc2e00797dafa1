"""`benchmarks/before_after.py`'s verdicts: medians, ranges and which way is faster."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import before_after


def test_throughput_within_and_beyond_before_range():
    before = [10.0, 12.0, 11.0, 9.0, 13.0]  # median 11, range [9, 13]
    same = before_after.summarise(before, [9.5, 9.2, 9.8, 9.1, 9.9], larger_is_faster=True)
    assert same["before"] == {"median": 11.0, "min": 9.0, "max": 13.0}
    assert same["after"]["median"] == 9.5
    assert same["ratio_after_over_before"] == pytest.approx(9.5 / 11.0, rel=1e-15)
    assert same["within_before_range"] and not same["faster"] and same["same_or_faster"]
    faster = before_after.summarise(before, [14.0, 15.0, 13.5], larger_is_faster=True)
    assert faster["faster"] and not faster["within_before_range"] and faster["same_or_faster"]
    slower = before_after.summarise(before, [8.0, 8.5, 8.9], larger_is_faster=True)
    assert not slower["same_or_faster"]


def test_times_faster_is_smaller():
    before = [2.0, 2.2, 2.4]  # median 2.2, range [2.0, 2.4]
    assert before_after.summarise(before, [1.9, 1.8, 1.95], larger_is_faster=False)["faster"]
    slower = before_after.summarise(before, [2.5, 2.6], larger_is_faster=False)
    assert slower["after"]["median"] == pytest.approx(2.55, rel=1e-15)
    assert not slower["within_before_range"] and not slower["faster"] and not slower["same_or_faster"]


def test_only_names_the_measurements_it_knows(capsys):
    tree = str(Path(__file__).resolve().parent.parent)
    with pytest.raises(SystemExit) as stopped:
        before_after.main(["--before", tree, "--after", tree, "--out", "unused", "--only", "conservative,fitt"])
    assert stopped.value.code == 2
    assert "choose from conservative, damped_frictional, fit_iteration, fit" in capsys.readouterr().err
