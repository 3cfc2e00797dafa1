"""Large frequency × amplitude lock-in grids: chunked, streamed to disk, resumable, sharded.

`run_lockin_sweep` evaluates the runs of `lockin_grid` (the amplitude ramp from rest: the
upward-sweep branch) in chunks of `chunk_size` runs, each chunk one call of the fused host
kernel on the CPU (`hertzchain.driven.fused`, bead readings) or one batch on the SIMD axis,
split over the devices given (`jax.shard_map`: GPUs, or a CPU's cores as host devices with
`XLA_FLAGS=--xla_force_host_platform_device_count=K` set before JAX starts). Each finished
chunk is written at once, atomically, as its own Parquet file; a sweep restarted into the
same folder checks the manifest and computes only the chunks not on disk. The folder holds:

- `manifest.json`: the chain, the grid and the run options, the chunking;
- `chunks/chunk_NNNNN.parquet`: one file per finished chunk;
- `lockin.parquet`, `lockin.csv`: one row per run, in run order (frequency slowest):
  `run`, `frequency_hz`, `drive_amplitude_m`, then for each harmonic h `rms_<h>f` and
  `phase_<h>f_rad` (e.g. `rms_1f`, `rms_0.5f`; m/s for velocity, m for displacement);
- `lockin.png`: the RMS at the drive frequency against frequency, one curve per amplitude.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec

from ..io.atomic import finish_figure, write_json
from ..progress import Progress
from ..sweep import _read_parquet, _write_parquet, _write_table_csv
from . import fused
from .chain import DrivenChain
from .grid import LockinGrid, check_grid_arguments, lockin_runs, readout_options
from .kernel import DEFAULT_UNROLL

LOCKIN_SWEEP_FORMAT = "hertzchain-lockin-sweep/1"
_DEFAULT_CHUNK = 4096


class LockinSweepResult(NamedTuple):
    """Where a sweep stands: `complete`, `chunks_done`, `n_chunks`, `computed` (chunks this
    call computed), `grid` (the `LockinGrid` when complete, else None), `folder`."""

    complete: bool
    chunks_done: int
    n_chunks: int
    computed: int
    grid: LockinGrid | None
    folder: Path


def harmonic_column(h: float) -> str:
    """Column suffix of harmonic h: 1.0 -> "1f", 0.5 -> "0.5f"."""
    return f"{h:g}f"


def run_lockin_sweep(
    chain: DrivenChain,
    frequencies_hz,
    drive_amplitudes_m,
    folder,
    *,
    chunk_size: int | None = None,
    devices=None,
    max_chunks: int | None = None,
    plots: bool = True,
    progress: bool = True,
    **readout,
) -> LockinSweepResult:
    """Run (or resume) the lock-in grid `frequencies_hz` × `drive_amplitudes_m` into `folder`.

    **Arguments:** the chain and the grid as for `lockin_grid` (concrete); `chunk_size`: runs
    per chunk (default: all runs, at most 4096, a multiple of the device count); `devices`:
    split each chunk over these (default: all local devices); `max_chunks`: stop after
    computing this many (the rest on a later call); `plots`, `progress`: write `lockin.png`;
    report progress and ETA on stderr; `**readout`: the read-out, `lockin_grid`'s keywords
    `bead`, `quantity`, `harmonics`, `ramp_periods`, `hold_periods`, `window_periods`,
    `steps_per_period` and `contact`, with its defaults (`grid.READOUT_KEYWORDS`; any other
    keyword is refused).

    **Returns:** `LockinSweepResult`.
    """
    o = readout_options("run_lockin_sweep", **readout)
    harmonics = tuple(float(h) for h in o["harmonics"])
    check_grid_arguments(chain, frequencies_hz, drive_amplitudes_m, o["bead"], o["quantity"], harmonics,
                         o["ramp_periods"], o["hold_periods"], o["window_periods"], o["steps_per_period"],
                         o["contact"])
    frequencies = np.asarray(frequencies_hz, dtype=float)
    amplitudes = np.asarray(drive_amplitudes_m, dtype=float)
    folder = Path(folder)
    devices = list(jax.local_devices() if devices is None else devices)
    n_runs = frequencies.size * amplitudes.size
    if chunk_size is None:
        chunk_size = min(n_runs, _DEFAULT_CHUNK)
    if int(chunk_size) != chunk_size or chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive whole number of runs, got {chunk_size}.")
    chunk_size = len(devices) * math.ceil(int(chunk_size) / len(devices))
    n_chunks = math.ceil(n_runs / chunk_size)
    whole = ("bead", "ramp_periods", "hold_periods", "window_periods", "steps_per_period")
    options = o | {name: int(o[name]) for name in whole} | {
        "harmonics": list(harmonics), "contact": None if o["contact"] is None else int(o["contact"])}
    manifest = {
        "format": LOCKIN_SWEEP_FORMAT,
        "chain": chain.describe(),
        "frequencies_hz": frequencies.tolist(),
        "drive_amplitudes_m": amplitudes.tolist(),
        "options": options,
        "n_runs": n_runs,
        "chunk_size": chunk_size,
        "n_chunks": n_chunks,
    }
    manifest_path = folder / "manifest.json"
    if manifest_path.exists():
        existing = json.loads(manifest_path.read_text())
        if existing != json.loads(json.dumps(manifest)):
            differing = sorted(k for k in manifest if existing.get(k) != json.loads(json.dumps(manifest[k])))
            raise ValueError(f"{folder} holds a different sweep (differs in: {', '.join(differing)}); use another "
                             "output folder or delete this one.")
    else:
        write_json(manifest_path, manifest)
    run_frequency = np.repeat(frequencies, amplitudes.size)
    run_amplitude = np.tile(amplitudes, frequencies.size)
    todo = [i for i in range(n_chunks) if not _chunk_path(folder, i).exists()]
    if max_chunks is not None:
        todo = todo[: max(0, int(max_chunks))]
    bar = Progress(sum(min((i + 1) * chunk_size, n_runs) - i * chunk_size for i in todo), "lock-in sweep (runs)") \
        if progress and todo else None
    on_fused_kernel = (fused.runs(o["quantity"]) and chain.runs_on_fused_kernel
                       and all(d.platform == "cpu" for d in devices))
    evaluate = _chunk_function(tuple(devices) if len(devices) > 1 else None, on_fused_kernel)
    chain = chain.for_kernel()
    settings = tuple((name, tuple(value) if isinstance(value, list) else value) for name, value in options.items())
    for index in todo:
        start, stop = index * chunk_size, min((index + 1) * chunk_size, n_runs)
        pad = chunk_size - (stop - start)
        f = np.concatenate([run_frequency[start:stop], np.repeat(run_frequency[stop - 1], pad)])
        a = np.concatenate([run_amplitude[start:stop], np.repeat(run_amplitude[stop - 1], pad)])
        readings = np.asarray(evaluate(chain, jnp.asarray(f), jnp.asarray(a), settings))[:, : stop - start]
        columns = {"run": np.arange(start, stop, dtype=np.int64), "frequency_hz": run_frequency[start:stop],
                   "drive_amplitude_m": run_amplitude[start:stop]}
        for h, reading in zip(harmonics, readings):
            columns[f"rms_{harmonic_column(h)}"] = np.abs(reading) / np.sqrt(2.0)
            columns[f"phase_{harmonic_column(h)}_rad"] = np.angle(reading)
        _write_parquet(_chunk_path(folder, index), columns)
        if bar:
            bar.advance(stop - start)
    done = sum(_chunk_path(folder, i).exists() for i in range(n_chunks))
    if done < n_chunks:
        return LockinSweepResult(False, done, n_chunks, len(todo), None, folder)
    parts = [_read_parquet(_chunk_path(folder, i)) for i in range(n_chunks)]
    table = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    _write_parquet(folder / "lockin.parquet", table)
    _write_table_csv(folder / "lockin.csv", table)
    grid = _grid_from_table(table, frequencies, amplitudes, options)
    if plots:
        plot_lockin(grid, folder / "lockin.png")
    return LockinSweepResult(True, done, n_chunks, len(todo), grid, folder)


def read_lockin_sweep(folder) -> LockinGrid:
    """The `LockinGrid` of a finished sweep folder."""
    folder = Path(folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    options = manifest["options"]
    table = _read_parquet(folder / "lockin.parquet")
    return _grid_from_table(table, np.asarray(manifest["frequencies_hz"]), np.asarray(manifest["drive_amplitudes_m"]),
                            options)


def _grid_from_table(table, frequencies, amplitudes, options) -> LockinGrid:
    shape = (frequencies.size, amplitudes.size)
    harmonics = tuple(options["harmonics"])
    readings = np.stack([
        np.sqrt(2.0) * table[f"rms_{harmonic_column(h)}"].reshape(shape)
        * np.exp(1j * table[f"phase_{harmonic_column(h)}_rad"].reshape(shape))
        for h in harmonics
    ])
    return LockinGrid(jnp.asarray(readings), jnp.asarray(frequencies), jnp.asarray(amplitudes), harmonics,
                      options["quantity"], options["bead"], options["contact"])


def _chunk_path(folder: Path, index: int) -> Path:
    return folder / "chunks" / f"chunk_{index:05d}.parquet"


def _chunk_function(devices, on_fused_kernel: bool):
    """(chain, frequencies (B,), amplitudes (B,), settings) -> (n_harmonics, B) complex
    readings, compiled, the batch split over `devices` when given (on the fused kernel where
    `on_fused_kernel`); `settings`: the manifest's run options as a tuple of (name, value)
    pairs (static)."""

    def local(chain, frequency, amplitude, settings):
        return lockin_runs(chain, frequency, amplitude, **dict(settings), unroll=DEFAULT_UNROLL,
                           on_fused_kernel=on_fused_kernel)

    if devices is None:
        return eqx.filter_jit(local)
    mesh = Mesh(np.asarray(devices), ("batch",))

    @eqx.filter_jit
    def sharded(chain, frequency, amplitude, settings):
        def per_device(c, f, a):
            return local(c, f, a, settings)

        specs = (PartitionSpec(), PartitionSpec("batch"), PartitionSpec("batch"))  # the chain on every device
        return jax.shard_map(per_device, mesh=mesh, in_specs=specs, out_specs=PartitionSpec(None, "batch"))(
            chain, frequency, amplitude)

    return sharded


def plot_lockin(grid: LockinGrid, path, *, max_curves: int = 12) -> None:
    """RMS at the drive frequency against frequency, one curve per drive amplitude (at most
    `max_curves`, evenly picked), PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    harmonic = grid.harmonics.index(1.0) if 1.0 in grid.harmonics else 0
    rms = np.asarray(grid.rms[harmonic])
    amplitudes = np.asarray(grid.drive_amplitudes_m)
    picked = np.unique(np.linspace(0, amplitudes.size - 1, min(max_curves, amplitudes.size)).round().astype(int))
    fig, ax = plt.subplots(figsize=(6.5, 4))
    colors = plt.cm.viridis(np.linspace(0.0, 1.0, picked.size))
    unit, scale = ("mm/s", 1e3) if grid.quantity == "velocity" else ("nm", 1e9)
    for color, j in zip(colors, picked):
        ax.plot(np.asarray(grid.frequencies_hz), scale * rms[:, j], color=color, lw=1,
                label=f"{1e9 * amplitudes[j]:.3g} nm")
    ax.set_xlabel("drive frequency (Hz)")
    ax.set_ylabel(f"bead {grid.bead} {grid.quantity}, lock-in RMS at {grid.harmonics[harmonic]:g} f ({unit})")
    ax.legend(title="drive amplitude", fontsize=6, ncol=2)
    ax.grid(True, alpha=0.3)
    finish_figure(fig, Path(path), dpi=120)
