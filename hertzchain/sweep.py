"""Sweeps over grids of setups: chunked, streamed to disk, resumable, sharded over devices.

A sweep is the outer product of value lists for scalar `ChainSetup` fields (impact velocity,
wall modulus, damping, friction, preload, ...), all run on one time grid (set by the most
demanding run). Runs are evaluated in chunks of `chunk_size` with `batched.solve_batched`
(the batch on the SIMD axis, split over all local devices), and each finished chunk is
written at once as its own Parquet file, atomically. The folder holds:

- `manifest.json`: what the sweep is: every field of the base setup (`setup_record`, walked
  generically, nested modules as class name and fields), the grid, every run option that
  changes the physics or the output, the chunk size, and `sweep_sha256`, the SHA-256 of all
  of it. A sweep restarted into the same folder must have the same manifest: one that
  differs in anything is refused naming each differing field with both values; otherwise
  only the chunks not on disk are computed, so an interrupted sweep resumes without
  recomputing or corrupting anything;
- `chunks/chunk_NNNNN.parquet`: one file per finished chunk, whose metadata holds the
  sweep's hash, its index and its runs; a chunk that does not match is refused by name;
- `sweep.parquet`, `sweep.csv`: the tidy table, one row per run, assembled from the chunks in
  run order once all are done (byte-identical whether or not the sweep was interrupted);
- `force_ratio.png`, `speed_vs_amplitude.png`: summary plots.

Columns of the table: `run` (index), the swept fields, then for each recorded channel
`peak_<channel>_n` (largest force over every step for contacts and the wall, over the
samples for sensors); for each recorded contact `arrival_<channel>_s` (time of the first
pulse's parabolic peak, `peaks.first_peak`) and `duration_<channel>_s` (the cos^6 duration
$2\\tau$ of its main pulse, `pulses.fit_cos6`; NaN where that fit did not converge, which
`duration_<channel>_converged` says); `speed_m_s` (distance between the first and
last recorded contact over the difference of their arrival times); `incident_peak_n` (first
pulse at the last recorded contact); `force_ratio` (wall peak / incident peak);
`energy_error_rel`, `dissipated_fraction`, `final_energy_fraction` (the energy balance at
the end, relative to the impact energy); `peak_over_yield` (the largest ratio of a contact's
peak force to its yield force, `ChainSetup.contact_yield_force_n`) and
`peak_over_yield_contact` (that contact; N: the wall), `result_finite`
(every peak force and energy finite: a row with false is not a result); then `setup_sha256`
(the hash of the base setup) and `setup.<field>`, the value of every field of the base
setup that is not swept and has one value (per-bead arrays of equal beads included), so
the table says what physics it holds. The Parquet file holds the hashes as metadata too.

Several hosts: start one process per host, call `jax.distributed.initialize(...)` in each
(the CLI's `--distributed`, with `--coordinator`, `--num-processes`, `--process-id` where the
cluster is not detected from SLURM, Open MPI or Kubernetes), then `run_sweep(...,
distributed=True)`; all write to the same folder (a shared file system), process k computing
the chunks k, k + P, k + 2P, ... on its own devices; process 0 assembles the table after a
barrier.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .batched import BatchedTraces, solve_batched
from .chain import ChainSetup
from .integrate import Recording
from .io.atomic import atomic_path, finish_figure, write_csv, write_json
from .io.setup_record import canonical, setup_record
from .native import kernel_record
from .progress import Progress
from .timegrid import DEFAULT_STEPS_PER_CONTACT, choose_time_grid
from .units import parse_quantity, unit_of_field
from .validation import check_run_size, check_step_stability, check_values, estimate_run_size

SWEEP_FORMAT = "hertzchain-sweep/2"
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
    """Parse one grid option `field=values`: a comma list (`3GPa,45GPa,203GPa`), a range
    `start:stop:count` (linear) or `start:stop:count:log` (log-spaced). Values are in the
    unit the field's name carries (`wall_youngs_pa`: Pa, `eta_s`: s), bare numbers SI, unit
    suffixes accepted (`eta_s=0:3us:4`)."""
    if "=" not in text:
        raise ValueError(f"--grid {text!r}: expected FIELD=VALUES, e.g. striker_velocity_m_s=0.1:1:10:log.")
    name, values = (part.strip() for part in text.split("=", 1))
    unit = unit_of_field(name)
    shape = (f"--grid {text!r}: values must be a comma list of numbers or start:stop:count[:log], "
             f"in {unit or 'SI units'} or with a unit suffix (e.g. wall_youngs_pa=3GPa,45GPa, "
             "eta_s=0:3us:4).")

    def number(part: str) -> float:
        return parse_quantity(part, unit, name=f"--grid {name}")

    if ":" in values:
        parts = values.split(":")
        if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] not in ("log", "lin")):
            raise ValueError(shape)
        start, stop = number(parts[0]), number(parts[1])
        try:
            count = int(parts[2])
        except ValueError:
            raise ValueError(shape) from None
        if count < 1:
            raise ValueError(f"--grid {text!r}: the count must be at least 1, got {count}.")
        if len(parts) == 4 and parts[3] == "log":
            if start <= 0 or stop <= 0:
                raise ValueError(f"--grid {text!r}: a log range needs positive start and stop.")
            array = np.geomspace(start, stop, count)
        else:
            array = np.linspace(start, stop, count)
    else:
        array = np.asarray([number(v) for v in values.split(",") if v.strip()])
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
        check_values(name, values, where="grid")
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
    """The contacts at 0.3 and 0.53 of an `n_beads` chain's length (6 and 11 of 21 beads): the
    contacts the command line records unless told others."""
    return tuple(sorted({min(max(round(f * n_beads), 0), n_beads - 1) for f in (0.3, 0.53)}))


def default_chunk_size(spec: SweepSpec, n_samples: int, n_devices: int) -> int:
    """Runs per chunk: the recorded samples of a chunk fit in about 256 MB."""
    channels = len(spec.contacts) + len(spec.setup.sensor_beads) + 1
    per_run = max(1, n_samples * channels * 8 * 3)
    size = max(1, min(_MAX_CHUNK, _CHUNK_BYTES // per_run, spec.n_runs))
    return n_devices * math.ceil(size / n_devices)


def sha256_of(record) -> str:
    """SHA-256 (hex) of the canonical JSON serialisation of `record` (sorted keys)."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def _manifest(spec: SweepSpec, chunk_size: int, n_chunks: int, grid) -> dict:
    setup = setup_record(spec.setup)
    manifest = {
        "format": SWEEP_FORMAT,
        "setup": setup,
        "setup_sha256": sha256_of(setup),
        "grid": {name: canonical(np.asarray(v, float)) for name, v in spec.grid.items()},
        "t_end_s": spec.t_end_s,
        "sample_interval_s": spec.sample_interval_s,
        "dt_s_requested": spec.dt_s,
        "steps_per_contact": spec.steps_per_contact,
        "dt_s": grid.dt_s,
        "steps_per_sample": grid.steps_per_sample,
        "n_samples": grid.n_samples,
        "contacts": list(spec.contacts),
        "n_runs": spec.n_runs,
        "chunk_size": chunk_size,
        "n_chunks": n_chunks,
    }
    return {**manifest, "sweep_sha256": sha256_of(manifest)}


def _flat(record, prefix: str = "") -> dict:
    """Dotted key -> value of a nested record (lists kept whole)."""
    if isinstance(record, dict):
        flat = {}
        for key, value in record.items():
            flat.update(_flat(value, f"{prefix}{key}."))
        return flat
    return {prefix[:-1]: record}


def _short(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _check_same_sweep(folder: Path, existing: dict, manifest: dict) -> None:
    """Refuse a folder whose manifest differs from this sweep's, naming every difference."""
    if existing.get("sweep_sha256") == manifest["sweep_sha256"] and existing == manifest:
        return
    old, new = _flat(existing), _flat(json.loads(json.dumps(manifest)))
    differing = [key for key in sorted(set(old) | set(new))
                 if key != "sweep_sha256" and key != "setup_sha256" and old.get(key) != new.get(key)]
    shown = "; ".join(f"{key} = {_short(old.get(key))} there, {_short(new.get(key))} now" for key in differing[:8])
    more = f" and {len(differing) - 8} more" if len(differing) > 8 else ""
    raise ValueError(
        f"{folder} holds a different sweep ({shown}{more}): its results are not this sweep's. "
        "Give a new folder (--out) or delete this one."
    )


_CHUNK_KEYS = (b"hertzchain.sweep_sha256", b"hertzchain.chunk", b"hertzchain.runs")


def _chunk_metadata(sweep_sha256: str, index: int, start: int, stop: int) -> dict:
    return dict(zip(_CHUNK_KEYS, (sweep_sha256, str(index), f"{start}:{stop}"), strict=True))


def _check_chunk(path: Path, sweep_sha256: str, index: int, start: int, stop: int) -> None:
    """Refuse a chunk file that was not written by this sweep for these runs."""
    import pyarrow.parquet as pq

    try:
        metadata = pq.read_schema(path).metadata or {}
    except (OSError, ValueError) as error:  # pyarrow's errors derive from these
        raise ValueError(f"{path} cannot be read as a sweep chunk ({error}); delete it and run again.") from error
    found = {key: metadata.get(key, b"").decode() for key in _CHUNK_KEYS}
    expected = {key.decode(): value for key, value in _chunk_metadata(sweep_sha256, index, start, stop).items()}
    if {key.decode(): value for key, value in found.items()} != expected:
        raise ValueError(
            f"{path} is not chunk {index} (runs {start}:{stop}) of this sweep (it holds sweep "
            f"{found[_CHUNK_KEYS[0]][:12] or 'unknown'}, chunk {found[_CHUNK_KEYS[1]] or '?'}, runs "
            f"{found[_CHUNK_KEYS[2]] or '?'}; this folder's sweep is {sweep_sha256[:12]}): delete it and run "
            "again to recompute it."
        )


def _constant_columns(record: dict, swept, n_rows: int) -> dict[str, np.ndarray]:
    """`setup.<field>` columns: every field of the setup record with one value, not swept."""
    columns = {}
    for key, value in _flat(record).items():
        if key in swept or key.endswith(".class") or key == "class":
            continue
        if isinstance(value, list):
            if not value or any(v != value[0] for v in value) or isinstance(value[0], (list, dict)):
                continue
            value = value[0]
        if isinstance(value, str) and value in ("inf", "-inf", "nan"):
            value = float(value)
        if value is None:
            continue
        columns[f"setup.{key}"] = np.full(n_rows, value)
    return columns


def _contact_positions_m(setup: ChainSetup, contacts) -> np.ndarray:
    """Position of contact K along the chain measured from contact 0, m (sum of diameters)."""
    diameters = 2.0 * np.asarray(setup.bead_radius_m)
    return np.asarray([np.sum(diameters[:k]) for k in contacts])


def summarize(setup: ChainSetup, contacts, out: BatchedTraces) -> dict[str, np.ndarray]:
    """The result columns of a chunk (see the module docstring)."""
    from . import peaks, pulses

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
            arrival, first = peaks.first_peak(time, trace)
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


def _write_parquet(path: Path, columns: dict, metadata: dict | None = None) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({k: np.asarray(v) for k, v in columns.items()}, metadata=metadata)
    with atomic_path(path) as temporary:
        pq.write_table(table, temporary)


def _read_parquet(path: Path) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    return {name: table.column(name).to_numpy() for name in table.column_names}


def _write_table_csv(path, columns: dict[str, np.ndarray]) -> None:
    """The table as CSV: integer columns as integers, text as text, the others as shortest
    round-trip floats."""
    def text(column):
        if column.dtype.kind in "iu":
            return [str(int(x)) for x in column]
        if column.dtype.kind in "OUS":
            return [str(x) for x in column]
        return [repr(float(x)) for x in column]

    formatted = [text(column) for column in columns.values()]
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


def _result_finite(columns: dict) -> np.ndarray:
    """Rows whose peak forces and energies are all finite."""
    keys = [k for k in columns if k.startswith("peak_") or k in ("energy_error_rel", "final_energy_fraction")]
    return np.all(np.stack([np.isfinite(np.asarray(columns[k], dtype=float)) for k in keys]), axis=0)


# Yield force of contacts 0..N-1 and the wall of each setup of a batch (one compiled program).
_yield_forces_n = jax.jit(jax.vmap(ChainSetup.contact_yield_force_n))


def _peak_over_yield(setup: ChainSetup, out: BatchedTraces) -> dict[str, np.ndarray]:
    """`peak_over_yield`, the largest peak force / yield force over the contacts and the wall
    of each run (batched setup), and `peak_over_yield_contact`, where (N: the wall)."""
    yield_force = np.asarray(_yield_forces_n(setup))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.nan_to_num(np.asarray(out.max_force_n) / yield_force, nan=0.0)
    return {"peak_over_yield": np.max(ratio, axis=1),
            "peak_over_yield_contact": np.argmax(ratio, axis=1).astype(np.int64)}


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
    check_size: bool = True,
) -> SweepResult:
    """Run (or resume) a sweep into `folder`.

    Before anything runs: every grid value is checked against `validation.RULES`, the step
    against the damping of the grid's extreme setups (`validation.check_step_stability`),
    the folder's manifest against this sweep's (any difference is refused, naming it), the
    chunks on disk against the manifest, and, with `check_size`, the memory and work of the
    runs to do (`validation.check_run_size`).

    **Arguments:**

    - `spec`: the `SweepSpec` (base setup, grid field -> values, run options).
    - `folder`: output folder; if it already holds this sweep, finished chunks are kept.
    - `chunk_size`: runs per chunk (default: sized so a chunk's samples take about 256 MB).
    - `devices`: devices to split each chunk over (default: all local devices).
    - `max_chunks`: stop after computing this many chunks (the rest on a later call).
    - `distributed`: this process is one of several (`jax.distributed.initialize()` has been
      called): it computes every P-th chunk; process 0 assembles the table.
    - `plots`, `progress`: write the summary plots; report progress and ETA on stderr.
    - `check_size`: refuse a sweep that needs more memory than is available or more work
      than `validation.MAX_BODY_STEPS` (False: run it anyway).

    **Returns:** `SweepResult`.

    **Raises:** `ValueError` for any of the checks above.
    """
    check_spec(spec)
    if not spec.contacts:
        spec = spec._replace(contacts=default_contacts(spec.setup.n_beads))
    folder = Path(folder)
    devices = list(jax.local_devices() if devices is None else devices)
    grid = time_grid(spec)
    check_step_stability(_whole_sweep_setup(spec, None), grid.dt_s, where="grid: ")
    if chunk_size is None:
        chunk_size = default_chunk_size(spec, grid.n_samples, len(devices))
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive number of runs, got {chunk_size}.")
    n_chunks = math.ceil(spec.n_runs / chunk_size)
    manifest = _manifest(spec, chunk_size, n_chunks, grid)
    sweep_sha256 = manifest["sweep_sha256"]
    manifest_path = folder / "manifest.json"
    existing = json.loads(manifest_path.read_text()) if manifest_path.exists() else None
    if existing is not None:
        existing.pop("kernel", None)  # which kernel computed the chunks so far is not what the sweep is
        _check_same_sweep(folder, existing, manifest)

    def runs(index):
        return index * chunk_size, min((index + 1) * chunk_size, spec.n_runs)

    mine = range(n_chunks)
    if distributed:
        mine = range(jax.process_index(), n_chunks, jax.process_count())
    todo = []
    for i in mine:
        if _chunk_path(folder, i).exists():
            _check_chunk(_chunk_path(folder, i), sweep_sha256, i, *runs(i))
        else:
            todo.append(i)
    if max_chunks is not None:
        todo = todo[: max(0, int(max_chunks))]
    sizes = {i: runs(i)[1] - runs(i)[0] for i in todo}
    if check_size:
        n_sensors = len(spec.setup.sensor_beads)
        check_run_size(estimate_run_size(
            n_runs_in_memory=min(chunk_size, spec.n_runs), n_runs=sum(sizes.values()),
            n_bodies=spec.setup.n_beads + 1 + n_sensors, n_channels=len(spec.contacts) + n_sensors + 1,
            n_samples=grid.n_samples, n_steps=grid.n_steps, n_table_values=spec.n_runs * (12 + 4 * len(spec.contacts)),
        ))
    if existing is None and (not distributed or jax.process_index() == 0):
        write_json(manifest_path, manifest)
    inputs = grid_table(spec)
    recording = Recording(tuple(spec.contacts))
    bar = Progress(sum(sizes.values()), "sweep (runs)") if progress and todo else None
    for index in todo:
        start, stop = runs(index)
        setup = _batched(spec.setup, inputs, start, stop)
        out = solve_batched(
            setup, grid, recording, devices=devices if len(devices) > 1 else None, pad_to=chunk_size
        )
        columns = {"run": np.arange(start, stop, dtype=np.int64)}
        columns.update({name: values[start:stop] for name, values in inputs.items()})
        columns.update(summarize(spec.setup, spec.contacts, out))
        columns.update(_peak_over_yield(setup, out))
        columns["result_finite"] = _result_finite(columns)
        _write_parquet(_chunk_path(folder, index), columns, _chunk_metadata(sweep_sha256, index, start, stop))
        if bar:
            bar.advance(stop - start)
    if todo and (not distributed or jax.process_index() == 0):  # the kernel of this run's chunks
        write_json(manifest_path, {**manifest, "kernel": kernel_record()})
    if distributed:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("hertzchain-sweep-chunks")
        if jax.process_index() != 0:
            return SweepResult(False, sum(_chunk_path(folder, i).exists() for i in range(n_chunks)),
                               n_chunks, len(todo), None, folder)
    done = sum(_chunk_path(folder, i).exists() for i in range(n_chunks))
    if done < n_chunks:
        return SweepResult(False, done, n_chunks, len(todo), None, folder)
    parts = []
    for i in range(n_chunks):
        _check_chunk(_chunk_path(folder, i), sweep_sha256, i, *runs(i))
        parts.append(_read_parquet(_chunk_path(folder, i)))
    table = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    n_rows = len(table["run"])
    table["setup_sha256"] = np.full(n_rows, manifest["setup_sha256"])
    table.update(_constant_columns(manifest["setup"], set(spec.grid), n_rows))
    metadata = {b"hertzchain.sweep_sha256": sweep_sha256, b"hertzchain.setup_sha256": manifest["setup_sha256"]}
    _write_parquet(folder / "sweep.parquet", table, metadata)
    _write_table_csv(folder / "sweep.csv", table)
    if plots:
        plot_sweep(table, folder)
    return SweepResult(True, done, n_chunks, len(todo), table, folder)


def nonfinite_runs(table: dict) -> np.ndarray:
    """Run indices of a sweep table whose result is not finite (`result_finite` false)."""
    return np.asarray(table["run"])[~np.asarray(table["result_finite"], dtype=bool)]


def table_yield_notice(table: dict, setup: ChainSetup) -> str | None:
    """One line naming the runs of a sweep table whose peak force exceeded a contact's yield
    force and those contacts, when the contacts are modelled elastic (else None)."""
    if setup.plasticity or "peak_over_yield" not in table:
        return None
    ratio = np.asarray(table["peak_over_yield"], dtype=float)
    over = ratio > 1.0
    if not np.any(over):
        return None
    where = sorted({int(k) for k in np.asarray(table["peak_over_yield_contact"])[over]})
    names = ", ".join("the wall" if k == setup.n_beads else f"contact {k}" for k in where)
    return (
        f"{int(np.sum(over))} of {ratio.size} runs exceed the yield force of {names} (peak/yield up to "
        f"{np.max(ratio):.3g}; columns peak_over_yield, peak_over_yield_contact): those contacts deform "
        "plastically, which the elastic model does not describe; add --plasticity thornton (or jackson_green) "
        "to model it, or lower the impact velocity."
    )


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
        x_name = "wall_youngs_pa" if "wall_youngs_pa" in table else _input_names(table)[0]
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
        finish_figure(fig, folder / "force_ratio.png", dpi=120)
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
        finish_figure(fig, folder / "speed_vs_amplitude.png", dpi=120)


_OUTPUT_PREFIXES = ("peak_", "arrival_", "duration_")
_OUTPUTS = ("speed_m_s", "incident_peak_n", "force_ratio", "energy_error_rel", "dissipated_fraction",
            "final_energy_fraction", "result_finite", "setup_sha256")


def _input_names(table) -> list[str]:
    return [k for k in table if k != "run" and k not in _OUTPUTS and not k.startswith(_OUTPUT_PREFIXES + ("setup.",))]


def _unit(name: str) -> str:
    for suffix, unit in (("_m_s", "m/s"), ("_pa", "Pa"), ("_s", "s"), ("_n", "N"), ("_m", "m"),
                         ("_kg", "kg")):
        if name.endswith(suffix):
            return unit
    return "1"
