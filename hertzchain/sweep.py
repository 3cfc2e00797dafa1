"""Sweeps over grids of setups: chunked, streamed to disk, resumable, sharded over devices.

A sweep is the outer product of value lists for scalar `ChainSetup` fields (impact velocity,
wall modulus, damping, friction, preload, ...), all run on one time grid (set by the most
demanding run). Runs are evaluated in chunks of `chunk_size` with `batched.solve_batched`
(the batch on the SIMD axis, split over all local devices), and each finished chunk is
written at once as its own Parquet file, atomically. The folder holds:

- `manifest.json`: what the sweep is (grid, base setup, run options, chunk size); a sweep
  restarted into the same folder checks it and computes only the chunks not on disk, so an
  interrupted sweep resumes without recomputing or corrupting anything;
- `chunks/chunk_NNNNN.parquet`: one file per finished chunk;
- `sweep.parquet`, `sweep.csv`: the tidy table, one row per run, assembled from the chunks in
  run order once all are done (byte-identical whether or not the sweep was interrupted);
- `force_ratio.png`, `speed_vs_amplitude.png`: summary plots.

Columns of the table: `run` (index), the swept fields, then for each recorded channel
`peak_<channel>_n` (largest force over every step for contacts and the wall, over the
samples for sensors); for each recorded contact `arrival_<channel>_s` (time of the first
pulse's parabolic peak, `pulses.first_peak`) and `duration_<channel>_s` (the cos^6 duration
$2\\tau$ of its main pulse, `pulses.fit_cos6`; NaN where that fit did not converge, which
`duration_<channel>_converged` says); `speed_m_s` (distance between the first and
last recorded contact over the difference of their arrival times); `incident_peak_n` (first
pulse at the last recorded contact); `force_ratio` (wall peak / incident peak);
`energy_error_rel`, `dissipated_fraction`, `final_energy_fraction` (the energy balance at
the end, relative to the impact energy).

Several hosts: start one process per host, call `jax.distributed.initialize(...)` in each
(the CLI's `--distributed`, with `--coordinator`, `--num-processes`, `--process-id` where the
cluster is not detected from SLURM, Open MPI or Kubernetes), then `run_sweep(...,
distributed=True)`; all write to the same folder (a shared file system), process k computing
the chunks k, k + P, k + 2P, ... on its own devices; process 0 assembles the table after a
barrier.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .atomic import atomic_path, save_figure, write_csv, write_json
from .batched import BatchedTraces, solve_batched
from .chain import ChainSetup
from .integrate import Recording
from .progress import Progress
from .timegrid import DEFAULT_STEPS_PER_CONTACT, choose_time_grid
from .tracefile import setup_header

SWEEP_FORMAT = "hertzchain-sweep/1"
# Recorded samples kept in memory per chunk (all channels), bounds the default chunk size.
_CHUNK_BYTES = 256 * 2**20
_MAX_CHUNK = 4096


class SweepSpec(NamedTuple):
    """A sweep: the base setup, the grid (field -> values) and the run options."""

    setup: ChainSetup
    grid: dict
    t_end_s: float = 2.5e-3
    sample_interval_s: float = 1e-6
    dt_s: float | None = None
    steps_per_contact: int = DEFAULT_STEPS_PER_CONTACT
    contacts: tuple[int, ...] = ()

    @property
    def n_runs(self) -> int:
        return int(np.prod([len(v) for v in self.grid.values()]))


def sweepable_fields(setup: ChainSetup) -> tuple[str, ...]:
    """Scalar numeric fields of a setup that a sweep can vary."""
    return tuple(
        name
        for name in (*setup.__dataclass_fields__, *setup.law_attributes)
        if isinstance(getattr(setup, name), jax.Array) and jnp.ndim(getattr(setup, name)) == 0
    )


def parse_grid(text: str) -> tuple[str, np.ndarray]:
    """Parse one grid option `field=values`: a comma list (`3e9,45e9,203e9`), a range
    `start:stop:count` (linear) or `start:stop:count:log` (log-spaced), SI units."""
    if "=" not in text:
        raise ValueError(f"--grid {text!r}: expected FIELD=VALUES, e.g. striker_velocity_m_s=0.1:1:10:log.")
    name, values = (part.strip() for part in text.split("=", 1))
    try:
        if ":" in values:
            parts = values.split(":")
            if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] not in ("log", "lin")):
                raise ValueError
            start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
            if count < 1:
                raise ValueError
            if len(parts) == 4 and parts[3] == "log":
                if start <= 0 or stop <= 0:
                    raise ValueError
                array = np.geomspace(start, stop, count)
            else:
                array = np.linspace(start, stop, count)
        else:
            array = np.asarray([float(v) for v in values.split(",") if v.strip()])
    except ValueError as error:
        raise ValueError(
            f"--grid {text!r}: values must be a comma list of numbers (SI) or start:stop:count[:log]."
        ) from error
    if array.size == 0:
        raise ValueError(f"--grid {text!r}: no values.")
    return name, array


def check_spec(spec: SweepSpec) -> None:
    """Raise ValueError naming the field for a grid the setup cannot take."""
    allowed = sweepable_fields(spec.setup)
    if not spec.grid:
        raise ValueError("A sweep needs at least one grid field, e.g. striker_velocity_m_s=0.1:1:10:log.")
    for name, values in spec.grid.items():
        if name not in allowed:
            raise ValueError(f"Cannot sweep {name!r}: sweepable fields are {', '.join(allowed)}.")
        if not np.all(np.isfinite(values) | (name == "wall_youngs_pa")):
            raise ValueError(f"{name}: grid values must be finite numbers, got {list(values)}.")
    for k in spec.contacts:
        if not 0 <= k < spec.setup.n_beads:
            raise ValueError(f"contacts: contact {k} is not in the chain (0..{spec.setup.n_beads - 1}).")


def grid_table(spec: SweepSpec) -> dict[str, np.ndarray]:
    """The input columns of every run, in run order (the first grid field varies slowest)."""
    names = list(spec.grid)
    rows = list(itertools.product(*(np.asarray(spec.grid[n], dtype=float) for n in names)))
    return {name: np.asarray([row[i] for row in rows]) for i, name in enumerate(names)}


def _batched(setup: ChainSetup, inputs: dict[str, np.ndarray], start: int, stop: int) -> ChainSetup:
    """The setup of runs start..stop-1 (every leaf with a leading batch axis)."""
    size = stop - start
    batched = jax.tree_util.tree_map(lambda leaf: jnp.broadcast_to(leaf, (size,) + jnp.shape(leaf)), setup)
    for name, values in inputs.items():
        batched = _replace(batched, name, jnp.asarray(values[start:stop]))
    return batched


def _replace(setup, name, value):
    import equinox as eqx

    return eqx.tree_at(lambda s: getattr(s, name), setup, value)


def _whole_sweep_setup(spec: SweepSpec, inputs) -> ChainSetup:
    """A batched setup holding, for each swept field, its extreme values (enough to choose
    the time grid: the contact times are monotonic in every sweepable field)."""
    corners = list(itertools.product(*([float(np.min(v)), float(np.max(v))] for v in spec.grid.values())))
    columns = {name: np.asarray([c[i] for c in corners]) for i, name in enumerate(spec.grid)}
    return _batched(spec.setup, columns, 0, len(corners))


def time_grid(spec: SweepSpec):
    """The one time grid of the whole sweep."""
    return choose_time_grid(
        _whole_sweep_setup(spec, None), t_end_s=spec.t_end_s, sample_interval_s=spec.sample_interval_s,
        dt_s=spec.dt_s, steps_per_contact=spec.steps_per_contact,
    )


def default_contacts(n_beads: int) -> tuple[int, ...]:
    """Two contacts at 0.3 N and 0.53 N (the command line's default)."""
    return tuple(sorted({min(max(round(f * n_beads), 0), n_beads - 1) for f in (0.3, 0.53)}))


def default_chunk_size(spec: SweepSpec, n_samples: int, n_devices: int) -> int:
    """Runs per chunk: the recorded samples of a chunk fit in about 256 MB."""
    channels = len(spec.contacts) + len(spec.setup.sensor_beads) + 1
    per_run = max(1, n_samples * channels * 8 * 3)
    size = max(1, min(_MAX_CHUNK, _CHUNK_BYTES // per_run, spec.n_runs))
    return n_devices * math.ceil(size / n_devices)


def _manifest(spec: SweepSpec, chunk_size: int, n_chunks: int, grid) -> dict:
    header = {k: (v if not isinstance(v, float) or math.isfinite(v) else str(v))
              for k, v in setup_header(spec.setup).items()}
    return {
        "format": SWEEP_FORMAT,
        "setup": header,
        "end": spec.setup.end,
        "sensor_beads": list(spec.setup.sensor_beads),
        "plasticity": spec.setup.plasticity,
        "grid": {name: [float(x) if math.isfinite(x) else str(x) for x in np.asarray(v, float)]
                 for name, v in spec.grid.items()},
        "t_end_s": spec.t_end_s,
        "sample_interval_s": spec.sample_interval_s,
        "dt_s": grid.dt_s,
        "steps_per_sample": grid.steps_per_sample,
        "n_samples": grid.n_samples,
        "contacts": list(spec.contacts),
        "n_runs": spec.n_runs,
        "chunk_size": chunk_size,
        "n_chunks": n_chunks,
    }


def _contact_positions_m(setup: ChainSetup, contacts) -> np.ndarray:
    """Position of contact K along the chain measured from contact 0, m (sum of diameters)."""
    diameters = 2.0 * np.asarray(setup.bead_radius_m)
    return np.asarray([np.sum(diameters[:k]) for k in contacts])


def summarize(setup: ChainSetup, contacts, out: BatchedTraces) -> dict[str, np.ndarray]:
    """The result columns of a chunk (see the module docstring)."""
    from . import pulses

    time = np.asarray(out.time_s)
    columns: dict[str, np.ndarray] = {}
    maxima = np.asarray(out.max_force_n)
    peak_times = {}
    for name in out.channel_names:
        # Via the host: the analysis then runs on one device whatever the run's sharding,
        # so sharded and unsharded sweeps give the same table to the last bit.
        trace = jnp.asarray(np.asarray(out.forces_n[name]))
        if name == "wall":
            columns["peak_wall_n"] = maxima[:, -1]
        elif name.startswith("contact_"):
            k = int(name.split("_")[1])
            columns[f"peak_{name}_n"] = maxima[:, k]
        else:
            columns[f"peak_{name}_n"] = np.max(np.asarray(trace), axis=1)
        if name.startswith("contact_"):
            arrival, first = pulses.first_peak(time, trace)
            peak_times[name] = (np.asarray(arrival), np.asarray(first))
            columns[f"arrival_{name}_s"] = np.asarray(arrival)
            fit = pulses.fit_cos6(time, trace)
            converged = np.asarray(fit.converged, dtype=bool)
            # a duration whose fit did not converge is not a measurement: NaN, and flagged
            columns[f"duration_{name}_s"] = np.where(converged, np.asarray(fit.duration_s), np.nan)
            columns[f"duration_{name}_converged"] = converged
    names = [f"contact_{k}" for k in contacts]
    if len(names) >= 2:
        positions = _contact_positions_m(setup, contacts)
        dt = peak_times[names[-1]][0] - peak_times[names[0]][0]
        with np.errstate(divide="ignore", invalid="ignore"):
            columns["speed_m_s"] = np.where(dt > 0, (positions[-1] - positions[0]) / dt, np.nan)
    if names:
        incident = peak_times[names[-1]][1]
        columns["incident_peak_n"] = incident
        with np.errstate(divide="ignore", invalid="ignore"):
            columns["force_ratio"] = np.where(incident > 0, maxima[:, -1] / incident, np.nan)
    initial = np.asarray(out.initial_energy_j)
    columns["energy_error_rel"] = np.asarray(out.energy_error_j) / initial
    columns["dissipated_fraction"] = np.asarray(out.dissipated_j) / initial
    columns["final_energy_fraction"] = (np.asarray(out.kinetic_j) + np.asarray(out.potential_j)) / initial
    return columns


def _chunk_path(folder: Path, index: int) -> Path:
    return folder / "chunks" / f"chunk_{index:05d}.parquet"


def _write_parquet(path: Path, columns: dict) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({k: np.asarray(v) for k, v in columns.items()})
    with atomic_path(path) as temporary:
        pq.write_table(table, temporary)


def _read_parquet(path: Path) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    return {name: table.column(name).to_numpy() for name in table.column_names}


def _write_table_csv(path, columns: dict[str, np.ndarray]) -> None:
    """The table as CSV: integer columns as integers, the others as shortest round-trip floats."""
    formatted = [
        [str(int(x)) for x in column] if column.dtype.kind in "iu" else [repr(float(x)) for x in column]
        for column in columns.values()
    ]
    write_csv(path, list(columns), zip(*formatted, strict=True))


class SweepResult(NamedTuple):
    """Where a sweep stands: `complete` (all chunks done and the table assembled),
    `chunks_done`, `n_chunks`, `computed` (chunks computed by this call), `table` (the columns
    when complete, else None), `folder`."""

    complete: bool
    chunks_done: int
    n_chunks: int
    computed: int
    table: dict | None
    folder: Path


def run_sweep(
    spec: SweepSpec,
    folder,
    *,
    chunk_size: int | None = None,
    devices=None,
    max_chunks: int | None = None,
    distributed: bool = False,
    plots: bool = True,
    progress: bool = True,
) -> SweepResult:
    """Run (or resume) a sweep into `folder`.

    **Arguments:**

    - `spec`: the `SweepSpec` (base setup, grid field -> values, run options).
    - `folder`: output folder; if it already holds this sweep, finished chunks are kept.
    - `chunk_size`: runs per chunk (default: sized so a chunk's samples take about 256 MB).
    - `devices`: devices to split each chunk over (default: all local devices).
    - `max_chunks`: stop after computing this many chunks (the rest on a later call).
    - `distributed`: this process is one of several (`jax.distributed.initialize()` has been
      called): it computes every P-th chunk; process 0 assembles the table.
    - `plots`, `progress`: write the summary plots; report progress and ETA on stderr.

    **Returns:** `SweepResult`.
    """
    check_spec(spec)
    if not spec.contacts:
        spec = spec._replace(contacts=default_contacts(spec.setup.n_beads))
    folder = Path(folder)
    devices = list(jax.local_devices() if devices is None else devices)
    grid = time_grid(spec)
    if chunk_size is None:
        chunk_size = default_chunk_size(spec, grid.n_samples, len(devices))
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive number of runs, got {chunk_size}.")
    n_chunks = math.ceil(spec.n_runs / chunk_size)
    manifest = _manifest(spec, chunk_size, n_chunks, grid)
    manifest_path = folder / "manifest.json"
    if manifest_path.exists():
        existing = json.loads(manifest_path.read_text())
        if existing != json.loads(json.dumps(manifest)):
            differing = sorted(k for k in manifest if existing.get(k) != json.loads(json.dumps(manifest[k])))
            raise ValueError(
                f"{folder} holds a different sweep (differs in: {', '.join(differing)}); "
                "use another output folder or delete this one."
            )
    elif not distributed or jax.process_index() == 0:
        write_json(manifest_path, manifest)
    inputs = grid_table(spec)
    mine = range(n_chunks)
    if distributed:
        mine = range(jax.process_index(), n_chunks, jax.process_count())
    todo = [i for i in mine if not _chunk_path(folder, i).exists()]
    if max_chunks is not None:
        todo = todo[: max(0, int(max_chunks))]
    recording = Recording(tuple(spec.contacts))
    sizes = {i: min((i + 1) * chunk_size, spec.n_runs) - i * chunk_size for i in todo}
    bar = Progress(sum(sizes.values()), "sweep (runs)") if progress and todo else None
    for index in todo:
        start, stop = index * chunk_size, min((index + 1) * chunk_size, spec.n_runs)
        setup = _batched(spec.setup, inputs, start, stop)
        out = solve_batched(
            setup, grid, recording, devices=devices if len(devices) > 1 else None, pad_to=chunk_size
        )
        columns = {"run": np.arange(start, stop, dtype=np.int64)}
        columns.update({name: values[start:stop] for name, values in inputs.items()})
        columns.update(summarize(spec.setup, spec.contacts, out))
        _write_parquet(_chunk_path(folder, index), columns)
        if bar:
            bar.advance(stop - start)
    if distributed:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("hertzchain-sweep-chunks")
        if jax.process_index() != 0:
            return SweepResult(False, sum(_chunk_path(folder, i).exists() for i in range(n_chunks)),
                               n_chunks, len(todo), None, folder)
    done = sum(_chunk_path(folder, i).exists() for i in range(n_chunks))
    if done < n_chunks:
        return SweepResult(False, done, n_chunks, len(todo), None, folder)
    parts = [_read_parquet(_chunk_path(folder, i)) for i in range(n_chunks)]
    table = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    _write_parquet(folder / "sweep.parquet", table)
    _write_table_csv(folder / "sweep.csv", table)
    if plots:
        plot_sweep(table, folder)
    return SweepResult(True, done, n_chunks, len(todo), table, folder)


def read_sweep(folder) -> dict[str, np.ndarray]:
    """The assembled table of a finished sweep, column -> array."""
    return _read_parquet(Path(folder) / "sweep.parquet")


def plot_sweep(table: dict[str, np.ndarray], folder) -> None:
    """Force ratio against wall modulus, and speed against incident amplitude (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = Path(folder)
    groups_by = "striker_velocity_m_s" if "striker_velocity_m_s" in table else None
    if "force_ratio" in table:
        x_name = "wall_youngs_pa" if "wall_youngs_pa" in table else next(
            k for k in table if k != "run"
        )
        fig, ax = plt.subplots(figsize=(6, 4))
        others = [k for k in table if k not in ("run", x_name) and k in _input_names(table)]
        keys = [tuple(table[k][i] for k in others) for i in range(len(table["run"]))]
        shown = sorted(set(keys))[:20]
        ax.set_prop_cycle(color=plt.cm.tab20(np.linspace(0.0, 1.0, 20))[: max(len(shown), 1)])
        for key in shown:
            mask = np.asarray([kk == key for kk in keys])
            order = np.argsort(table[x_name][mask])
            label = ", ".join(f"{k}={v:.3g}" for k, v in zip(others, key)) or None
            ax.plot(table[x_name][mask][order], table["force_ratio"][mask][order], "o-", ms=3, label=label)
        ax.set_xscale("log" if np.all(table[x_name] > 0) else "linear")
        ax.set_xlabel(f"{x_name} ({_unit(x_name)})")
        ax.set_ylabel("force ratio: wall peak / incident peak (1)")
        ax.grid(True, alpha=0.3)
        if others:
            ax.legend(fontsize=6)
        fig.tight_layout()
        save_figure(fig, folder / "force_ratio.png", dpi=120)
        plt.close(fig)
    if "speed_m_s" in table and "incident_peak_n" in table:
        fig, ax = plt.subplots(figsize=(6, 4))
        ok = np.isfinite(table["speed_m_s"]) & (table["incident_peak_n"] > 0)
        color = table[groups_by][ok] if groups_by else None
        scatter = ax.scatter(table["incident_peak_n"][ok], table["speed_m_s"][ok], c=color, s=10)
        if groups_by:
            fig.colorbar(scatter, ax=ax, label="striker_velocity_m_s (m/s)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("incident peak force (N)")
        ax.set_ylabel("pulse speed (m/s)")
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        save_figure(fig, folder / "speed_vs_amplitude.png", dpi=120)
        plt.close(fig)


_OUTPUT_PREFIXES = ("peak_", "arrival_", "duration_")
_OUTPUTS = ("speed_m_s", "incident_peak_n", "force_ratio", "energy_error_rel", "dissipated_fraction",
            "final_energy_fraction")


def _input_names(table) -> list[str]:
    return [k for k in table if k != "run" and k not in _OUTPUTS and not k.startswith(_OUTPUT_PREFIXES)]


def _unit(name: str) -> str:
    for suffix, unit in (("_m_s", "m/s"), ("_pa", "Pa"), ("_s", "s"), ("_n", "N"), ("_m", "m"),
                         ("_kg", "kg")):
        if name.endswith(suffix):
            return unit
    return "1"
