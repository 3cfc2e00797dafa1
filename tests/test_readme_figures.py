"""The figure check (`benchmarks/check_readme_figures.py`): the project's documents pass it,
and on small made-up documents it rejects what the rule says it rejects: a figure without a
source, an invented figure, a figure cited to the wrong key, a key or file that is not there."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("check_readme_figures", ROOT / "benchmarks" / "check_readme_figures.py")
check = importlib.util.module_from_spec(spec)
spec.loader.exec_module(check)

RESULT = "benchmarks/results/fit_bench/latest.json"
STORED = {"cases": {"paper": {"cold": {"wall_s": 6.802808, "phases_s": {"reading": 0.5120}},
                              "first": {"wall_s": 41.1888}}},
          "kernel": {"run_ms": 0.571, "speedup": 1.46, "bead_steps_per_s": 2.2157e10, "share": 0.1234},
          "runs": [{"wall_s": 12.0}, {"wall_s": 19.04}]}


def test_the_projects_documents_cite_every_figure():
    assert check.problems() == []


def _tree(tmp_path, readme, docs=None):
    (tmp_path / "benchmarks" / "results" / "fit_bench").mkdir(parents=True)
    (tmp_path / RESULT).write_text(json.dumps(STORED))
    (tmp_path / "benchmarks" / "results" / "fit_bench" / "latest.csv").write_text("case,wall_s\npaper,6.80\nbrass,7.12\n")
    (tmp_path / "benchmarks" / "results" / "fit_bench" / "latest.time").write_text("real\t2m13.4s\nuser\t4m1.0s\n")
    (tmp_path / "README.md").write_text(readme)
    for name, text in (docs or {}).items():
        (tmp_path / "docs").mkdir(exist_ok=True)
        (tmp_path / "docs" / name).write_text(text)
    return tmp_path


def _notes(**keys):
    return "".join(f"\n[^{name}]: `{source}`\n" for name, source in keys.items())


def test_cited_figures_pass_at_their_printed_precision(tmp_path):
    text = ("A fit takes 6.8 s[^cold] cold and 41 s[^first] the first time; reading takes 512 ms[^read].\n"
            "One chain took 0.57 ms[^run] at η = 2 µs, 1.5×[^speed] faster, 2.2e10 bead-steps/s[^rate].\n"
            "The runs took 12–19 s[^runs]; its share of the wall time is 12.3 %[^share].\n"
            "| case | time |\n|---|---|\n| paper | 6.80 s[^row] |\n"
            "The whole job took 2m13.4s, real 133.4 s[^line].\n"
            "Inputs are not figures: η = 2 µs, 0.5 % noise, `--t-end 2.5ms` and\n```\nfit --timeout 999 s\n```\n")
    text += _notes(cold=f"{RESULT}#cases.paper.cold.wall_s", first=f"{RESULT}#cases.paper.first.wall_s",
                   read=f"{RESULT}#cases.paper.cold.phases_s.reading", run=f"{RESULT}#kernel.run_ms",
                   speed=f"{RESULT}#kernel.speedup", rate=f"{RESULT}#kernel.bead_steps_per_s",
                   share=f"{RESULT}#kernel.share", row="benchmarks/results/fit_bench/latest.csv#0.wall_s",
                   line="benchmarks/results/fit_bench/latest.time#L1")
    text = text.replace("[^runs]", "[^runs]") + f"\n[^runs]: `{RESULT}#runs.0.wall_s`, `{RESULT}#runs.1.wall_s`\n"
    root = _tree(tmp_path, text)
    # "2m13.4s" is not a figure of rule 1 (no unit after a number alone); 133.4 s is on line 1
    assert check.problems(root, allowed=()) == ["README.md:7: 133.4 s: 133.4 is not the stored value at its "
                                                 "precision (benchmarks/results/fit_bench/latest.time#L1 = 2, 13.4)"]


def test_an_invented_figure_is_rejected(tmp_path):
    root = _tree(tmp_path, "A fit takes 6.9 s[^cold].\nThe speed-up is 1.4×[^speed].\n"
                 + _notes(cold=f"{RESULT}#cases.paper.cold.wall_s", speed=f"{RESULT}#kernel.speedup"))
    assert check.problems(root, allowed=()) == [
        f"README.md:1: 6.9 s: 6.9 is not the stored value at its precision ({RESULT}#cases.paper.cold.wall_s = 6.80281)",
        f"README.md:2: 1.4×: 1.4 is not the stored value at its precision ({RESULT}#kernel.speedup = 1.46)"]


def test_a_figure_cited_to_the_wrong_key_is_rejected(tmp_path):
    # 41 s is stored, but as the first run's time, not the cold one's
    root = _tree(tmp_path, "The cold fit took 41 s[^cold].\n" + _notes(cold=f"{RESULT}#cases.paper.cold.wall_s"))
    assert check.problems(root, allowed=()) == [
        f"README.md:1: 41 s: 41 is not the stored value at its precision ({RESULT}#cases.paper.cold.wall_s = 6.80281)"]
    # a time stored in milliseconds is converted: 571 µs is the run, 571 ms is not
    root = _tree(tmp_path / "b", "One run took 571 µs[^run]; the other took 571 ms[^run].\n"
                 + _notes(run=f"{RESULT}#kernel.run_ms"))
    assert check.problems(root, allowed=()) == [
        f"README.md:1: 571 ms: 571 is not the stored value at its precision ({RESULT}#kernel.run_ms = 0.571)"]


def test_a_range_needs_both_ends_stored(tmp_path):
    root = _tree(tmp_path, "The runs took 12–20 s[^runs].\n"
                 f"\n[^runs]: `{RESULT}#runs.0.wall_s`, `{RESULT}#runs.1.wall_s`\n")
    assert check.problems(root, allowed=()) == [
        f"README.md:1: 12–20 s: 20 is not the stored value at its precision ({RESULT}#runs.0.wall_s = 12, "
        f"{RESULT}#runs.1.wall_s = 19.04)"]


def test_uncited_missing_and_broken_sources_are_rejected(tmp_path):
    root = _tree(tmp_path, "Intro.\nA fit takes 6.8 s on 2 cores.\n",
                 docs={"page.md": "It took 3 s[^gone], 4 s[^nokey] and 5 s[^nofile] and 6 s[^empty].\n"
                       + _notes(gone=f"{RESULT}#cases.brass.cold.wall_s", nokey=f"{RESULT}#cases.paper",
                                nofile="benchmarks/results/nothing.json#a")
                       + "\n[^empty]: the fit benchmark\n"})
    assert check.problems(root, allowed=()) == [
        "README.md:2: 6.8 s: cites no source (add a footnote naming `path#key`)",
        f"docs/page.md:1: 3 s: {RESULT}#cases.brass.cold.wall_s: 'brass'",
        f"docs/page.md:1: 4 s: {RESULT}#cases.paper: 'cases.paper holds dict, not a number'",
        "docs/page.md:1: 5 s: benchmarks/results/nothing.json#a: benchmarks/results/nothing.json does not exist",
        "docs/page.md:1: 6 s: footnote [^empty] names no `path#key`"]


def test_allowed_entries_must_still_be_in_the_text(tmp_path):
    root = _tree(tmp_path, "Every diagnosis should take at most 120 s.\n")
    allowed = (("README.md", "120 s", "a target"),)
    assert check.problems(root, allowed=allowed) == []
    (root / "README.md").write_text("Every diagnosis should be quick.\n")
    assert check.problems(root, allowed=allowed) == [
        "README.md: 120 s is listed in ALLOWED but no longer in the text; delete the entry"]
