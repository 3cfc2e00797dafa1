"""Bad inputs and faults a new user meets, each run as that user would: is it refused with one
line naming the field and the fix, or computed right?

    python benchmarks/input_checks.py [--only NAME,...] [--out benchmarks/results/input_checks]

Each case runs `python -m hertzchain ...` in its own scratch folder under /tmp (small chains;
a shared 5-bead trace file made once by `hertzchain synth`), and records the command, its
exit status, the first line of what it printed (the first `error:` or `warning:` line of
stderr, else the first line of stderr or stdout), the verdict (`refused`: exit 2 with a
one-line message; `computed`: exit 0 or 3; `traceback`; `signal`) and whether that is what
the case expects (`expect`: `refuse`, `compute`, or `warn`: computed with a warning line),
with any check of the files it left (`files_ok`). The rows that need a full diagnosis run
are not here. Writes `latest.json` into --out after every case (the 1-minute load average
and the command's wall time beside each: under load).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
LYDON = ROOT.parent / "shared" / "data" / "real" / "lydon-2015"

SMALL = ["--n-beads", "5", "--t-end", "0.2ms"]
SWEEP = ["sweep", *SMALL, "--grid", "striker_velocity_m_s=0.1:1:4:log", "--grid", "eta_s=0,1e-6",
         "--chunk-size", "2", "--out", "s"]
FIT = ["fit", "trace.csv", "--params", "eta_s", "--quiet", "--no-plots", "--out", "f"]


def _hertzchain(folder: Path, argv, env=None) -> subprocess.CompletedProcess:
    environment = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg") | (env or {})
    return subprocess.run([sys.executable, "-m", "hertzchain", *argv], cwd=folder, env=environment,
                          capture_output=True, text=True, check=False, timeout=900)


# --- what a case prepares in its folder -----------------------------------------------------------

def _trace(folder: Path, base: Path) -> None:
    shutil.copy(base / "trace.csv", folder / "trace.csv")


def _edit_trace(pattern: str, replacement: str):
    def prepare(folder: Path, base: Path) -> None:
        text = (base / "trace.csv").read_text()
        edited, n = re.subn(pattern, replacement, text, flags=re.MULTILINE)
        if n == 0:
            raise RuntimeError(f"the trace header has no line matching {pattern!r}")
        (folder / "trace.csv").write_text(edited)
    return prepare


def _raw_trace(transform):
    def prepare(folder: Path, base: Path) -> None:
        (folder / "trace.csv").write_bytes(transform((base / "trace.csv").read_bytes()))
    return prepare


def _finished_sweep(*extra):
    def prepare(folder: Path, base: Path) -> None:
        done = _hertzchain(folder, [*SWEEP, *extra])
        if done.returncode != 0:
            raise RuntimeError(f"the first sweep failed: {done.stderr[-500:]}")
    return prepare


def _scope_lab(label: str | None = None, files: str | None = None):
    def prepare(folder: Path, base: Path) -> None:
        import docs_commands

        (folder / "out" / "synth").mkdir(parents=True)
        shutil.copy(base / "trace.csv", folder / "out" / "synth" / "trace.csv")
        docs_commands.write_scope_lab(folder)
        text = (folder / "experiment.toml").read_text()
        if files is not None:
            text = text.replace('files = ["shot1.csv"]', f"files = [{json.dumps(files)}]")
        if label is not None:
            text = text.replace('files = ["shot1.csv"]', f'files = ["shot1.csv"]\nlabel = {json.dumps(label)}')
        (folder / "experiment.toml").write_text(text)
    return prepare


def _driven(amplitude_file: str | None = None, kind: str | None = None):
    def prepare(folder: Path, base: Path) -> None:
        text = (ROOT / "examples" / "lydon2015" / "single_bead_bending.toml").read_text()
        if amplitude_file is not None:
            text = re.sub(r'^amplitude_file = ".*"$', f"amplitude_file = {json.dumps(amplitude_file)}", text,
                          flags=re.MULTILINE)
        if kind is not None:
            text = text.replace('kind = "driven"', f"kind = {json.dumps(kind)}")
        (folder / "driven.toml").write_text(text)
    return prepare


def _kernel_cache(size_bytes: int):
    """A copy of the library cache with the main chain library cut to `size_bytes`."""
    def prepare(folder: Path, base: Path) -> None:
        from hertzchain import native

        source = Path(native.cache_dir()) if hasattr(native, "cache_dir") else Path.home() / ".cache" / "hertzchain"
        cache = folder / "cache"
        cache.mkdir()
        for path in source.glob("*.so*"):
            shutil.copy(path, cache / path.name)
        main_libraries = [p for p in cache.glob("chain_kernel-*.so") if re.fullmatch(r"chain_kernel-[0-9a-f]+\.so", p.name)]
        if not main_libraries:
            raise RuntimeError(f"no built chain library in {source}: run `hertzchain kernel` first")
        for path in main_libraries:
            with open(path, "r+b") as handle:
                handle.truncate(min(size_bytes, path.stat().st_size))
    return prepare


def _contact_file(name: str, content: str | bytes):
    def prepare(folder: Path, base: Path) -> None:
        data = content if isinstance(content, bytes) else content.encode()
        (folder / name).write_bytes(data)
    return prepare


def _earlier_fit(folder: Path, base: Path) -> None:
    """Two shots fitted into f/ with the per-file figures; the case fits one of them again."""
    shutil.copy(base / "trace.csv", folder / "trace.csv")
    shutil.copy(base / "trace2.csv", folder / "trace2.csv")
    done = _hertzchain(folder, ["fit", "trace.csv", "trace2.csv", "--params", "eta_s", "--quiet", "--out", "f",
                                "--per-trace-plots"])
    if done.returncode != 0:
        raise RuntimeError(f"the first fit failed: {done.stderr[-500:]}")


def _read_only_out(folder: Path, base: Path) -> None:
    (folder / "ro").mkdir()
    (folder / "ro").chmod(0o555)


def _out_is_a_file(folder: Path, base: Path) -> None:
    _trace(folder, base)
    (folder / "afile").write_text("not a folder\n")


# --- the cases: (name, the row, argv, prepare, expect, files check) -------------------------

def _nothing_escaped(folder: Path) -> bool:
    return not list(folder.glob("out/escaped*")) and not (folder / "escaped").exists()


def _no_stale_files(folder: Path) -> bool:
    return not list((folder / "f").glob("*trace2*"))


def _no_echo(folder: Path, output: str) -> bool:
    return Path("/etc/hostname").read_text().strip() not in output


CASES = (
    # a resumed sweep with other physics
    ("sweep_resume_other_mu", "resumed sweep, changed --mu", [*SWEEP, "--mu", "0.3"],
     _finished_sweep("--mu", "0.1", "--max-chunks", "2"), "refuse"),
    ("sweep_rerun_dashpot", "finished sweep run again with --dashpot 50", [*SWEEP, "--dashpot", "50"],
     _finished_sweep(), "refuse"),
    # eta_s is on the grid, which sets every run's eta: --eta changes no run, the table stands
    ("sweep_rerun_eta", "finished sweep run again with --eta 0 (eta_s is on the grid)", [*SWEEP, "--eta", "0"],
     _finished_sweep(), "compute"),
    # cached kernel libraries
    ("library_truncated", "a truncated cached library (800000 bytes)", ["kernel"], _kernel_cache(800000), "compute"),
    ("library_empty", "an empty cached library", ["kernel"], _kernel_cache(0), "compute"),
    # labels and paths of an import
    ("import_label_parent", "[[shot]] label = \"../escaped\"", ["import", "experiment.toml", "--out", "out/import"],
     _scope_lab(label="../escaped"), "refuse", _nothing_escaped),
    ("import_label_absolute", "[[shot]] label = an absolute path", ["import", "experiment.toml", "--out", "out/import"],
     _scope_lab(label="/tmp/escaped-hertzchain-label"), "refuse",
     lambda folder: not Path("/tmp/escaped-hertzchain-label").exists()),
    ("import_file_outside", "a shot file outside the experiment's folder (/etc/hostname)",
     ["import", "experiment.toml", "--out", "out/import"], _scope_lab(files="/etc/hostname"), "refuse", None, _no_echo),
    # a measurement of one kind given as another
    ("driven_tongue_as_bending", "the single bead's BifurcationTongue amplitude file as a bending sweep",
     ["fit", "driven.toml", "--data-dir", str(LYDON), "--out", "f", "--quiet"],
     _driven("SingleBead/BifurcationTongue/SingleBeadBif Signal Amplitude_02013Jul3_9h28m45s.txt"), "refuse"),
    ("driven_kind_typo", "kind = \"drivn\"", ["fit", "driven.toml", "--data-dir", str(LYDON), "--out", "f"],
     _driven(kind="drivn"), "refuse"),
    # grid values
    *((f"grid_{name}", f"--grid {grid}", ["sweep", *SMALL, "--grid", grid, "--out", "s"], None, "refuse")
      for name, grid in (("negative_eta", "eta_s=-1e-6,1e-6"), ("negative_mu", "mu=-0.1,0.1"),
                         ("poisson_07", "wall_poisson=0.7"), ("dashpot_unstable", "dashpot_n_s_m=1e6"),
                         ("eta_2s", "eta_s=2"), ("negative_velocity", "striker_velocity_m_s=-0.1"),
                         ("zero_wall", "wall_youngs_pa=0"))),
    ("simulate_eta_2", "--eta 2 (meaning 2 us)", ["simulate", *SMALL, "--eta", "2", "--out", "o"], None, "refuse"),
    # the fit's inputs
    ("fit_noise_zero", "--noise-std 0", [*FIT, "--noise-std", "0"], _trace, "refuse"),
    ("fit_noise_negative", "--noise-std -1", [*FIT, "--noise-std=-1"], _trace, "refuse"),
    ("fit_header_noise_zero", "a header noise_std_n of 0", FIT,
     _edit_trace(r"^# noise_std_n(_\w+)? = .*$", "# noise_std_n\\1 = 0"), "refuse"),
    ("fit_fixed_mu_negative", "--fixed mu=-1", [*FIT, "--fixed", "mu=-1"], _trace, "refuse"),
    *((f"fit_steps_per_contact_{value.lstrip('-')}{'_negative' if value.startswith('-') else ''}",
       f"--steps-per-contact {value}", [*FIT, f"--steps-per-contact={value}"], _trace, "refuse")
      for value in ("5", "-3", "0")),
    ("fit_same_file_twice", "the same file given twice", ["fit", "trace.csv", "trace.csv", *FIT[2:]], _trace,
     "refuse"),
    ("fit_prior_width_without_unit", "--prior bead_youngs_pa=+-4 (no unit)", [*FIT, "--prior", "bead_youngs_pa=+-4"],
     _trace, "refuse"),
    # sizes
    ("simulate_t_end_1e3", "--t-end 1e3", ["simulate", "--n-beads", "5", "--t-end", "1e3", "--out", "o"], None,
     "refuse"),
    ("sweep_1e8_runs", "a grid of 1e8 runs", ["sweep", *SMALL, "--grid", "striker_velocity_m_s=0.1:1:100000000",
                                             "--out", "s"], None, "refuse"),
    ("simulate_1e6_beads", "1e6 beads", ["simulate", "--n-beads", "1000000", "--out", "o"], None, "refuse"),
    ("fit_too_many_steps", "a fit past the bead-step limit (--steps-per-contact 1e9)",
     [*FIT, "--steps-per-contact", "1000000000"], _trace, "refuse"),
    # errors of the file system and of parsing
    ("out_read_only", "a read-only output folder", ["simulate", *SMALL, "--out", "ro/sim"], _read_only_out, "refuse"),
    ("fit_out_is_a_file", "--out naming a file", [*FIT[:-1], "afile"], _out_is_a_file, "refuse"),
    ("fit_header_n_beads_1e400", "header n_beads = 1e400", FIT, _edit_trace(r"^# n_beads = .*$", "# n_beads = 1e400"),
     "refuse"),
    ("trace_bom", "a trace file with a UTF-8 BOM", FIT, _raw_trace(lambda data: b"\xef\xbb\xbf" + data), "compute"),
    ("trace_semicolons", "a ;-delimited trace file", FIT,
     _raw_trace(lambda data: re.sub(rb"^([^#][^\n]*)$", lambda m: m.group(1).replace(b",", b";"), data,
                                    flags=re.MULTILINE)), "refuse"),
    ("trace_not_utf8", "a trace file that is not UTF-8", FIT,
     _raw_trace(lambda data: data.replace(b"# ", b"# \xe9", 1)), "refuse"),
    ("contact_short_rows", "contact CSV with a short row", ["contact", "c.csv", "--material", "steel_440C",
                                                            "--radius", "3.175mm", "--out", "c"],
     _contact_file("c.csv", "approach_m,force_n\n0,0\n1e-6\n"), "refuse"),
    ("contact_long_rows", "contact CSV with a long row", ["contact", "c.csv", "--material", "steel_440C",
                                                          "--radius", "3.175mm", "--out", "c"],
     _contact_file("c.csv", "approach_m,force_n\n0,0\n1,5e-6,2,5\n"), "refuse"),
    ("contact_comma_decimals", "contact CSV with comma decimals", ["contact", "c.csv", "--material", "steel_440C",
                                                                   "--radius", "3.175mm", "--out", "c"],
     _contact_file("c.csv", 'approach_m;force_n\n0;0\n"1,5e-6";"2,5"\n'), "refuse"),
    ("contact_fake_mat", "a fake .mat given to contact", ["contact", "c.mat", "--material", "steel_440C",
                                                          "--radius", "3.175mm", "--out", "c"],
     _contact_file("c.mat", b"this is not a MATLAB file" * 8), "refuse"),
    ("contact_radius_13", "contact --radius 13 (meaning 13 mm)",
     ["contact", str(ROOT.parent / "shared" / "data" / "real" / "burgoyne-2014" / "ExperimentalData" / "force10.mat"),
      "--material", "steel_440C", "--radius", "13", "--out", "c"], None, "refuse",
     lambda folder: not (folder / "c").exists()),
    # output folders
    ("fit_stale_files", "a fit into the folder of an earlier fit of more files", FIT, _earlier_fit, "compute",
     _no_stale_files),
    # yield
    ("sweep_beyond_yield", "a sweep at 1 m/s, beyond the yield force",
     ["sweep", *SMALL, "--grid", "striker_velocity_m_s=0.1,1", "--out", "s"], None, "warn"),
)


def _first_line(done: subprocess.CompletedProcess) -> str:
    for line in done.stderr.splitlines():
        if re.search(r"\b(error|warning):", line):
            return line.strip()
    for stream in (done.stderr, done.stdout):
        lines = [line.strip() for line in stream.splitlines() if line.strip()]
        if lines:
            return lines[0]
    return ""


def _verdict(done: subprocess.CompletedProcess) -> str:
    if done.returncode < 0 or done.returncode >= 128:
        return "signal"
    if "Traceback (most recent call last)" in done.stderr:
        return "traceback"
    if done.returncode == 2:
        errors = [line for line in done.stderr.splitlines() if "error:" in line]
        return "refused" if len(errors) == 1 else "refused (not one line)"
    return "computed" if done.returncode in (0, 3) else f"exit {done.returncode}"


def run_case(case, base: Path) -> dict:
    name, what, argv, prepare, expect, *checks = case
    files_check = checks[0] if checks else None
    output_check = checks[1] if len(checks) > 1 else None
    folder = Path(tempfile.mkdtemp(prefix=f"hertzchain-input-{name}-"))
    env = {}
    if prepare is not None:
        prepare(folder, base)
    if (folder / "cache").is_dir():
        env["HERTZCHAIN_CACHE"] = str(folder / "cache")
    load = os.getloadavg()[0]
    began = time.perf_counter()
    done = _hertzchain(folder, argv, env)
    wall = time.perf_counter() - began
    verdict = _verdict(done)
    warned = any("warning:" in line for line in done.stderr.splitlines())
    expected = {"refuse": verdict == "refused", "compute": verdict == "computed",
                "warn": verdict == "computed" and warned}[expect]
    row = {"name": name, "what": what, "command": "hertzchain " + " ".join(argv), "exit_status": done.returncode,
           "first_line": _first_line(done), "verdict": verdict, "expect": expect, "as_expected": expected,
           "wall_s_under_load": round(wall, 1), "load_average_1min_before": round(load, 2), "folder": str(folder)}
    if files_check is not None:
        row["files_ok"] = bool(files_check(folder))
    if output_check is not None:
        row["output_ok"] = bool(output_check(folder, done.stdout + done.stderr))
    (folder / "ro").chmod(0o755) if (folder / "ro").exists() else None
    return row


def make_base() -> Path:
    """The shared inputs: two 5-bead trace files (0.2 and 0.4 m/s) written by `hertzchain synth`."""
    base = Path(tempfile.mkdtemp(prefix="hertzchain-input-base-"))
    done = _hertzchain(base, ["synth", "--n-beads", "5", "--velocities", "0.2,0.4", "--contacts", "2",
                              "--t-end", "0.3ms", "--noise-fraction", "0.005", "--out", "synth"])
    if done.returncode != 0:
        raise RuntimeError(f"hertzchain synth failed: {done.stderr[-1000:]}")
    first, second = sorted((base / "synth").glob("*.csv"))
    shutil.copy(first, base / "trace.csv")
    shutil.copy(second, base / "trace2.csv")
    return base


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="", help="comma-separated case names [every case]")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "input_checks",
                        help="folder of latest.json [benchmarks/results/input_checks]")
    args = parser.parse_args(argv)
    from hertzchain.io.atomic import write_json

    chosen = {n.strip() for n in args.only.split(",") if n.strip()}
    cases = [case for case in CASES if not chosen or case[0] in chosen]
    unknown = chosen - {case[0] for case in CASES}
    if unknown:
        parser.error(f"no case {', '.join(sorted(unknown))}; cases: {', '.join(case[0] for case in CASES)}")
    base = make_base()
    path = args.out / "latest.json"
    # --only: the chosen cases' rows replace theirs in the stored record, the others are kept
    kept = json.loads(path.read_text())["rows"] if chosen and path.exists() else []
    rows = []
    for case in cases:
        try:
            row = run_case(case, base)
        except (RuntimeError, OSError, subprocess.TimeoutExpired) as error:
            row = {"name": case[0], "what": case[1], "verdict": "not run", "as_expected": False,
                   "first_line": " ".join(str(error).split())[:300]}
        rows.append(row)
        print(f"{'ok ' if row['as_expected'] else 'NO '} {row['name']}: {row.get('exit_status')} {row['verdict']}: "
              f"{row['first_line'][:160]}", flush=True)
        done = {r["name"] for r in rows}
        every = [r for r in kept if r["name"] not in done] + rows
        every.sort(key=lambda r: [case[0] for case in CASES].index(r["name"]))
        summary = {"cases": len(every), "as_expected": sum(r["as_expected"] for r in every),
                   "cpus": os.cpu_count(), "rows": every}
        write_json(path, summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
