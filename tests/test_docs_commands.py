"""The documentation's commands as written: each `hertzchain ...` command of README.md and
docs/**/*.md parses with the command line's own parsers (nothing runs;
`benchmarks/docs_commands.py`, whose `--run` also runs a newcomer's path through them)."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import docs_commands


@pytest.fixture(scope="module")
def rows():
    return docs_commands.check_all()


def test_every_command_of_the_docs_parses(rows):
    assert len(rows) >= 25  # the tour, the how-to pages, the reproductions
    assert {row["argv"][0] for row in rows} >= {"simulate", "sweep", "synth", "fit", "diagnose", "import",
                                                "analyze", "contact"}
    failures = [f"{row['file']}:{row['line']}: {row['failure']}" for row in rows if row["failure"]]
    assert failures == []


def test_the_pages_under_docs_write_the_parameters_by_their_names(rows):
    # README.md is held to the parse check alone: a previous name still works (with a
    # warning) for one release, and its text is the lead's to change
    previous = [f"{row['file']}:{row['line']}: {row['previous_name']}" for row in rows
                if row["previous_name"] and row["file"].startswith("docs")]
    assert previous == []


def test_the_check_rejects_a_misspelt_option_and_names_a_previous_name(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("Text `hertzchain fit x.csv` in a sentence.\n\n```bash\n"
                    "hertzchain fit run*.csv --paramz eta_s --out out/fit   # a typo\n"
                    "hertzchain fit run*.csv --params eta,mu \\\n    --out out/fit\n"
                    "hertzchain fit: error: an example of what a command prints\n"
                    "hertzchain sweep --grid eta_s=0,1e-6 [--chunk-size N]\n```\n\n"
                    "    hertzchain diagnose a.csv --free wall_youngs_pa\n")
    commands = docs_commands.extract_commands(page)
    assert [c["line"] for c in commands] == [4, 5, 11]  # the synopsis and the printed line are no commands
    assert commands[1]["argv"] == ["fit", "run*.csv", "--params", "eta,mu", "--out", "out/fit"]
    typo, previous, indented = (docs_commands.parse_check(c["argv"]) for c in commands)
    assert typo[0] == "hertzchain: error: unrecognized arguments: --paramz eta_s" and typo[1] is None
    assert previous == (None, ("--params: 'eta' is now called 'eta_s'; write eta_s (the old name is accepted until "
                              "the next release)."))
    assert indented == (None, None)
