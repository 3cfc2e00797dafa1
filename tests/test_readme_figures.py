"""The README figure check (`benchmarks/check_readme_figures.py`): the repository's two
READMEs pass it, and on small made-up documents it finds what the rule says it finds."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("check_readme_figures", ROOT / "benchmarks" / "check_readme_figures.py")
check = importlib.util.module_from_spec(spec)
spec.loader.exec_module(check)


def test_every_checked_readme_figure_is_stored():
    problems, _ = check.missing()
    assert problems == []


def _tree(tmp_path, readme, bench_readme="", results=None):
    (tmp_path / "benchmarks" / "results").mkdir(parents=True)
    (tmp_path / "README.md").write_text(readme)
    (tmp_path / "benchmarks" / "README.md").write_text(bench_readme)
    stored = results or {"fit": {"timings_s": {"total": 12.34}, "converged": True},
                         "kernel": {"bead_steps_per_s": 2.2157e10, "run_s": 0.000571, "speedup": 1.46}}
    (tmp_path / "benchmarks" / "results" / "bench.json").write_text(json.dumps(stored))
    (tmp_path / "benchmarks" / "results" / "notes.md").write_text("| job | wall (s) |\n|---|---|\n| diagnose | 157.2 |\n")
    return tmp_path


def test_stored_figures_pass_at_their_printed_precision(tmp_path):
    root = _tree(tmp_path, "A fit takes 12.3 s. The diagnosis took 157 s.\n"
                           "One chain: 0.57 ms per chain, 1.5× faster than before.\n"
                           "Inputs are not checked: η = 2 µs, 0.5 % noise, `--t-end 2.5ms` and\n"
                           "```\nhertzchain fit --timeout 999 s\n```\n",
                 "Throughput 2.2e10 bead-steps/s at 0.3 m/s.\n")
    assert check.missing(root, allowed=(), unstored=()) == ([], [])


def test_unstored_figures_fail_with_file_and_line(tmp_path):
    root = _tree(tmp_path, "Intro.\nA fit takes 12.6 s on 2 cores.\n", "It runs 3.1e10 bead-steps/s, 2.5× faster.\n")
    problems, _ = check.missing(root, allowed=(), unstored=())
    assert problems == ["README.md:2: 12.6 s (time) is in no stored result",
                        "benchmarks/README.md:1: 3.1e10 bead-steps/s (throughput) is in no stored result",
                        "benchmarks/README.md:1: 2.5× (ratio) is in no stored result"]
    # a stored time does not vouch for a ratio or a throughput of the same number
    root = _tree(tmp_path / "b", "The batch is 12.34× faster.\n")
    assert check.missing(root, allowed=(), unstored=())[0] == [
        "README.md:1: 12.34× (ratio) is in no stored result"]


def test_allowed_and_unstored_entries_must_still_be_in_the_text(tmp_path):
    root = _tree(tmp_path, "Every diagnosis within 120 s; the old profile said 17 µs per step.\n")
    allowed = (("README.md", "120 s", "a target"),)
    unstored = (("README.md", "17 µs", "no file"),)
    problems, listed = check.missing(root, allowed=allowed, unstored=unstored)
    assert problems == [] and listed == ["README.md:1: 17 µs (time) is listed in UNSTORED"]
    (root / "README.md").write_text("Every diagnosis within 120 s.\n")
    problems, _ = check.missing(root, allowed=allowed, unstored=unstored)
    assert problems == ["README.md: 17 µs is listed in ALLOWED or UNSTORED but no longer in the text; delete the entry"]


def test_a_table_cell_listing_several_runs_stores_each(tmp_path):
    """A stored table cell "a / b / c" (the runs of one case) stores each of its numbers, of
    its column's kind; a number in none of them still fails."""
    root = _tree(tmp_path, "Numba ran at 1.28e9 bead-steps/s.\n")
    (root / "benchmarks" / "results" / "quick.md").write_text(
        "| case | Numba bead-steps/s |\n|---|---|\n| damped | 1.23e+09 / 1.276e+09 / 1.25e+09 |\n")
    assert check.missing(root, allowed=(), unstored=()) == ([], [])
    (root / "README.md").write_text("Numba ran at 1.29e9 bead-steps/s.\n")
    assert check.missing(root, allowed=(), unstored=())[0] == [
        "README.md:1: 1.29e9 bead-steps/s (throughput) is in no stored result"]
