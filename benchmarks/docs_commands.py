"""The documentation's commands as written: every `hertzchain ...` command of README.md and
docs/**/*.md parses, and a newcomer's path through the docs runs.

    python benchmarks/docs_commands.py [--check] [--run] [--out benchmarks/results/docs_commands]

`--check` (the default): every command in a fenced or indented code block of README.md and
the pages under docs/ (continuation lines joined, `# comments` dropped, example output
lines such as `hertzchain fit: error: ...` skipped) is parsed by the command line's own
argparse parsers (`hertzchain.cli.main` with the command's `run` replaced by a check that
does no work), and a `hertzchain fit`, `diagnose` or `design` of trace files has its
parameter names resolved as the fit resolves them (`fitting.parameters.resolve_name`), a
`hertzchain sensitivity` as it resolves them (`hertzchain.parameters.resolve_name`): an
unknown name is a failure, a previous name (still read, with a warning, for one release) is
listed apart.
Prints one line per command that fails or uses a previous name; exit 1 if any fails.

`--run`: the newcomer's path (simulate, sweep, synth, fit, diagnose, import, analyze, a
driven fit, a contact calibration), each command copied from the page named beside it, run
as a new user would, `python -m hertzchain` in a fresh HOME (an empty cache: the kernels
are built as a first use builds them) in a scratch folder under /tmp beside a link to this
checkout's `examples/` and to the shared data (`../shared`, as the docs write it). The
import step needs a lab's scope files: the scratch folder gets them written from the synth
step's traces (volts = force x sensitivity, `format = "csv"`), with the docs' example
experiment file's keys. Writes `latest.json` into --out after each step: per command its
page, exit status, wall time (s, under whatever load the machine has: the 1-minute load
average before and after each step is stored beside it), the process CPU time of the
command (s, `resource.getrusage` of the children) and the last lines of its output.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import resource
import shlex
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# The options of each command that name parameters: (option, a list of names, or of
# NAME=VALUE assignments). A repeatable option (a list of values) is read item by item.
_NAME_OPTIONS = {"fit": (("params", False), ("profile", False), ("start", True), ("fixed", True)),
                 "diagnose": (("free", False), ("nuisances", False)),
                 "design": (("params", False), ("nuisances", False)),
                 "sensitivity": (("params", False), ("sweep", True), ("box", True))}


def documents(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown page under docs/, in a stable order."""
    return [root / "README.md"] + sorted((root / "docs").rglob("*.md"))


def _code_lines(text: str):
    """(line number, line) of each line inside a fenced (```) or an indented (4 spaces or a
    tab, after a blank line) code block."""
    fenced, indented, previous_blank = False, False, True
    for number, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced:
            yield number, line
            continue
        if line.startswith(("    ", "\t")) and (indented or previous_blank):
            indented = True
            yield number, line
        else:
            indented = False
        previous_blank = not line.strip()


def extract_commands(path: Path) -> list[dict]:
    """The `hertzchain ...` commands of one page: dicts of `file`, `line` and `argv` (the
    arguments after `hertzchain`), continuation lines joined and comments dropped."""
    commands, pending, start = [], None, 0
    for number, line in _code_lines(path.read_text(encoding="utf-8")):
        text = line.strip()
        text = text.removeprefix("$ ")
        if pending is None:
            words = text.split()
            if len(words) < 2 or words[0] != "hertzchain" or words[1].endswith(":"):
                continue  # not a command, or an example of what a command prints
            pending, start = "", number
        pending += " " + text
        if pending.endswith("\\"):
            pending = pending[:-1]
            continue
        argv = shlex.split(pending, comments=True)[1:]
        if not any(word.startswith("[") for word in argv):  # else a synopsis ("[--option VALUE]")
            name = str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)
            commands.append({"file": name, "line": start, "argv": argv})
        pending = None
    return commands


class PreviousName(Exception):
    """A parameter written with its previous name (`fitting.parameters.ParameterNameWarning`)."""


def _name_check(command: str, args) -> None:
    """A fit, diagnosis, design or sensitivity study: each parameter name resolved as the
    command resolves it (a previous name's warning raised as an error)."""
    from fitting.driven.experiment import is_driven_experiment
    from fitting.parameters import ParameterNameWarning, resolve_label
    from hertzchain.parameters import resolve_name

    files = getattr(args, "files", ())
    if getattr(args, "data_dir", None) is not None or any(Path(f).is_file() and is_driven_experiment(f) for f in files):
        return  # a driven experiment names its own parameters (fitting.driven.experiment)
    resolve = resolve_name if command == "sensitivity" else resolve_label
    with warnings.catch_warnings():
        warnings.simplefilter("error", ParameterNameWarning)
        try:
            for option, assignments in _NAME_OPTIONS[command]:
                given = getattr(args, option) or ""
                items = given.split(",") if isinstance(given, str) else given
                names = [part.split("=", 1)[0].strip() if assignments else part.strip() for part in items]
                for name in filter(None, names):
                    resolve(name, where=f"--{option}")
            for prior in getattr(args, "prior", ()):
                resolve_label(prior.split("=", 1)[0].strip(), where="--prior")
        except ParameterNameWarning as previous_name:
            raise PreviousName(str(previous_name)) from None


def parse_check(argv: list[str]) -> tuple[str | None, str | None]:
    """(failure, previous name): each None, or the one line saying why `hertzchain ARGV` does
    not parse, or which parameter it writes by its previous name. Nothing runs: the command's
    `run` is replaced while it parses."""
    from hertzchain.cli import COMMANDS, main

    if not argv or argv[0] not in COMMANDS:
        return f"no command {argv[0] if argv else ''!r}; commands: {', '.join(COMMANDS)}", None
    module = importlib.import_module(COMMANDS[argv[0]][0])
    real_run, seen = module.run, []

    def check(args):
        seen.append(args)
        if argv[0] in _NAME_OPTIONS:
            _name_check(argv[0], args)
        return 0

    module.run = check
    errors = io.StringIO()
    try:
        with contextlib.redirect_stderr(errors), contextlib.redirect_stdout(io.StringIO()):
            code = main(argv)
    except SystemExit as exit_:
        code = exit_.code
    except PreviousName as previous:
        return None, str(previous)
    finally:
        module.run = real_run
    if code == 0 and seen:
        return None, None
    lines = [line for line in errors.getvalue().splitlines() if line.strip()]
    return (lines[-1] if lines else f"exit {code}"), None


def check_all(root: Path = ROOT) -> list[dict]:
    """Every command of the docs with its parse result (`failure`, `previous_name`: None or
    the one line of `parse_check`)."""
    rows = []
    for path in documents(root):
        for command in extract_commands(path):
            failure, previous = parse_check(command["argv"])
            rows.append(command | {"failure": failure, "previous_name": previous})
    return rows


# --- the newcomer's path ------------------------------------------------------------------------

# (page the command is copied from, the command as written there); run in order, in one
# scratch folder. The sweep and the diagnosis are the docs' own, at their sizes; the fit is
# README.md's, with the previous name `eta` (read with a warning).
NEWCOMER = (
    ("README.md", "hertzchain kernel"),
    ("README.md", "hertzchain simulate --eta 2us --wall-youngs 5GPa --contacts 6,11 --out out/simulate"),
    ("docs/how-to/sweeps.md", ("hertzchain sweep --grid striker_velocity_m_s=0.1:1:10:log "
     "--grid wall_youngs_pa=3e9,45e9,203e9 --grid eta_s=0,2e-6 --out out/sweep")),
    ("README.md", ("hertzchain synth --velocities 0.05,0.1,0.3 --contacts 6,11 --eta 2us --mu 0.19 "
     "--noise-fraction 0.005 --bits 8 --out out/synth")),
    ("README.md", "hertzchain fit out/synth/*.csv --params eta_s,mu,C --out out/fit"),
    ("README.md", "hertzchain diagnose out/synth/*.csv --out out/diagnose"),
    ("docs/how-to/experiment-files.md", "hertzchain import experiment.toml --out out/import"),
    ("docs/how-to/experiment-files.md", "hertzchain analyze experiment.toml --out out/analyze"),
    ("README.md", ("hertzchain fit examples/lydon2015/single_bead_bending.toml "
     "--data-dir ../shared/data/real/lydon-2015 --out out/driven")),
    ("README.md", ("hertzchain contact ../shared/data/real/burgoyne-2014/ExperimentalData/force10.mat "
     "--material steel_440C --radius 3.175mm --damping --out out/contact")),
)

# The sensitivities of the import step's scope channels (the synth traces' wall, then their
# first recorded contact), V/N.
_SENSITIVITIES_V_PER_N = (0.1124, 0.05)
# Samples the stand-in scope records before the trigger.
_PRE_TRIGGER_SAMPLES = 100


def write_scope_lab(folder: Path) -> None:
    """An `experiment.toml` with the docs' keys and its scope files (generic CSV, volts),
    written from the synth step's trace files in `folder/out/synth`."""
    from hertzchain.io.tracefile import read_trace

    traces = sorted((folder / "out" / "synth").glob("*.csv"))
    first = read_trace(traces[0])
    header = first.header
    recorded = ["wall"] + [c for c in first.channels if c.startswith("contact_")][:1]
    sensitivity = dict(zip(recorded, _SENSITIVITIES_V_PER_N))
    chain = {key: header[key] for key in ("n_beads", "bead_radius_m", "bead_density_kg_m3", "bead_youngs_pa",
                                          "bead_poisson", "wall_youngs_pa", "wall_poisson", "striker_mass_kg")}
    text = "[chain]\n" + "".join(f"{key} = {json.dumps(value)}\n" for key, value in chain.items())
    text += '\n[scope]\nformat = "csv"\ntime_zero = "trigger"\n'
    for k, (channel, volts_per_n) in enumerate(sensitivity.items(), start=1):
        text += (f'\n[[channel]]\nsource = "CH{k}"\nmeasures = "{channel}"\nsensitivity_v_per_n = {volts_per_n}\n'
                 'coupling = "dc"\n')
    noise = np.random.default_rng(0)
    for number, path in enumerate(traces, start=1):
        trace = read_trace(path)
        name = f"shot{number}.csv"
        lines = ["time_s," + ",".join(f"CH{k}" for k in range(1, len(sensitivity) + 1))]
        # a scope's pre-trigger segment: the channels' noise (the header's sigma) before the impact
        interval = float(trace.time_s[1] - trace.time_s[0])
        for i in range(-_PRE_TRIGGER_SAMPLES, 1):  # up to t = 0, one interval before the first sample
            volts = [noise.normal(0.0, trace.channel_noise_std_n(c) or 0.0) * s for c, s in sensitivity.items()]
            lines.append(f"{i * interval:.9g}," + ",".join(f"{v:.6g}" for v in volts))
        for i, t in enumerate(trace.time_s):
            volts = [trace.channels[c][i] * s for c, s in sensitivity.items()]
            lines.append(f"{t:.9g}," + ",".join(f"{v:.6g}" for v in volts))
        (folder / name).write_text("\n".join(lines) + "\n")
        text += f'\n[[shot]]\nfiles = ["{name}"]\nstriker_velocity_m_s = {trace.header["striker_velocity_m_s"]}\n'
    (folder / "experiment.toml").write_text(text)


def run_newcomer(out: Path, *, again: Path | None = None, words: tuple[str, ...] = ()) -> dict:
    """The newcomer's path in a fresh HOME and scratch folder; the record of every step.
    `again`: an earlier run's scratch folder, in which the steps whose command contains one of
    `words` run again (their records replace the earlier ones in latest.json)."""
    scratch = again or Path(tempfile.mkdtemp(prefix="hertzchain-newcomer-"))
    home, work = scratch / "home", scratch / "checkout"
    if again is None:
        home.mkdir()
        work.mkdir()
        (work / "examples").symlink_to(ROOT / "examples")
        (scratch / "shared").symlink_to(ROOT.parent / "shared")
    env = {k: v for k, v in os.environ.items() if not k.startswith("HERTZCHAIN")}
    env |= {"HOME": str(home), "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    record = {"scratch": str(scratch), "fresh_home": True, "cpus": os.cpu_count(), "steps": []}
    if again is not None:
        record = json.loads((out / "latest.json").read_text())["newcomer"]
    for page, command in NEWCOMER:
        if again is not None and not any(word in command for word in words):
            continue
        if " import " in command and (again is not None or not (work / "experiment.toml").exists()):
            write_scope_lab(work)
        argv = [sys.executable, "-m", "hertzchain", *shlex.split(command)[1:]]
        argv = [str(p) for a in argv for p in (sorted(work.glob(a)) if "*" in a else [a])]
        load_before, cpu_before = os.getloadavg()[0], resource.getrusage(resource.RUSAGE_CHILDREN)
        began = time.perf_counter()
        done = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - began
        cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
        output = (done.stdout + done.stderr).strip().splitlines()
        record["steps"] = [step for step in record["steps"] if step["command"] != command]
        record["steps"].append({
            "page": page, "command": command, "exit_status": done.returncode, "wall_s_under_load": round(wall, 1),
            "cpu_s": round(cpu_after.ru_utime + cpu_after.ru_stime - cpu_before.ru_utime - cpu_before.ru_stime, 1),
            "load_average_1min_before": round(load_before, 2), "load_average_1min_after": round(os.getloadavg()[0], 2),
            "output_tail": output[-4:]})
        print(f"{done.returncode:3d} {wall:7.1f} s  {command}", flush=True)
        record["steps"].sort(key=lambda step: [c for _, c in NEWCOMER].index(step["command"]))
        _write(out, {"newcomer": record})
    return record


def _write(out: Path, part: dict) -> None:
    from hertzchain.io.atomic import write_json

    path = out / "latest.json"
    previous = json.loads(path.read_text()) if path.exists() else {}
    out.mkdir(parents=True, exist_ok=True)
    write_json(path, previous | part)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="parse every command of the docs (the default)")
    parser.add_argument("--run", action="store_true", help="run the newcomer's path in a fresh HOME")
    parser.add_argument("--again", type=Path, metavar="SCRATCH",
                        help="with --run: run again, in an earlier run's scratch folder, the steps whose command "
                        "holds one of --steps")
    parser.add_argument("--steps", default="", help="with --again: comma-separated words, e.g. import,analyze")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "docs_commands",
                        help="folder of latest.json [benchmarks/results/docs_commands]")
    args = parser.parse_args(argv)
    failed = 0
    if args.check or not args.run:
        rows = check_all()
        failed = sum(row["failure"] is not None for row in rows)
        previous = sum(row["previous_name"] is not None for row in rows)
        for row in rows:
            if row["failure"] or row["previous_name"]:
                print(f"{row['file']}:{row['line']}: hertzchain {shlex.join(row['argv'])}: "
                      f"{row['failure'] or 'previous name: ' + row['previous_name']}")
        print(f"{len(rows)} commands, {failed} fail to parse, {previous} use a previous parameter name")
        _write(args.out, {"parse": {"commands": len(rows), "failed": failed, "previous_names": previous,
                                    "rows": rows}})
    if args.run:
        run_newcomer(args.out, again=args.again, words=tuple(w for w in args.steps.split(",") if w))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
