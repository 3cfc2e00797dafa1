"""Driven measurements described by an experiment file (`kind = "driven"`).

A lab that drives a precompressed chain harmonically and records a bead's motion through a
lock-in keeps: the chain (beads and contacts, the static precompression), the drive (a piezo:
its calibration in m per lock-in output volt, with its uncertainty), the sensor (a laser
vibrometer: (m/s) per volt, read as the lock-in's RMS at the drive frequency) and the sweep
files as the instruments wrote them. That is the experiment file::

    kind = "driven"
    label = "single bead, resonance bending"

    [chain]
    n_beads = 1
    bead_mass_kg = 0.028
    bead_radius_m = "9.525mm"
    bead_youngs_pa = "193GPa"
    bead_poisson = 0.3
    face_youngs_pa = "193GPa"      # the piezo's face (sphere-flat contact 0)
    face_poisson = 0.3
    wall_youngs_pa = "193GPa"      # the wall (sphere-flat contact n)
    wall_poisson = 0.3
    precompression_n = 4.5
    # contact_kappa_n_m1p5 = [...] # n + 1 Hertz constants, instead of the materials

    [drive]
    calibration_m_per_v = 6.834e-7
    calibration_uncertainty = 0.41 # relative (1 sigma)

    [sensor]
    bead = 1                       # 1 = next to the piezo
    quantity = "velocity"
    calibration_m_s_per_v = 0.02125
    reading = "lockin_rms"         # the lock-in's R: RMS at the drive frequency

    [sweep]
    amplitude_file = "SingleBead/.../SingleBead_Bending Signal Amplitude_02013Jul3_10h29m15s.txt"
    # exclude_hz = [[2150, 2300]]  # bands left out of fits (say why in a comment)

    [model]                        # how the model emulates the lock-in (hertzchain.driven)
    ramp_periods = 25
    hold_periods = 35
    window_periods = 4
    steps_per_period = 48

File paths are relative to the data folder given on the command line (`--data-dir`), so that
the description can live beside the code and the data stay where the lab keeps them.

**Several measurements, several runs.** Instead of `[sweep]`, a file may list every measurement
the lab made on the apparatus, each a `[[measurement]]` table with its `kind`
(`hertzchain.driven.measurements`: `bending`, `tongue`, `loop`, `scope`), the `run` it belongs
to (measurements of one run share its precompression and drive calibration; runs on other
days need not) and its files::

    [[measurement]]
    kind = "bending"
    run = "2013-07-03 10:29"
    amplitude_file = "SingleBead/LinearToNonlinearBending/SingleBead_Bending Signal Amplitude_0....txt"
    drive_calibration_m_per_v = 6.834e-7   # this run's (default: [drive]'s), and its uncertainty:
    drive_calibration_uncertainty = 0.41   # relative, 1 sigma (default: [drive]'s)

    [[measurement]]
    kind = "tongue"                        # upward amplitude sweeps at fixed frequencies
    run = "2013-07-03 09:28"
    amplitude_file = "SingleBead/BifurcationTongue/SingleBeadBif Signal Amplitude_0....txt"
    subharmonic_file = "SingleBead/BifurcationTongue/SingleBeadBif Signal Amplitude_3....txt"

    [[measurement]]
    kind = "loop"                          # one frequency, amplitude up then down
    run = "2013-07-04 13:45"
    amplitude_file = "..."
    subharmonic_file = "..."

    [[measurement]]
    kind = "scope"                         # time records at each step of a sweep
    run = "2013-07-04 13:45"
    scope_file = "...ScopeShots_middle....txt.txt"
    levels_file = "...SingleBeadSingleRun Signal Amplitude_0....txt"   # the sweep's steps

    [fit]                                  # the joint fit (`fitting.driven.joint`)
    shared = ["contact_kappa_n_m1p5", "damping_rate_per_s"]
    per_run = ["precompression_n", "drive_scale"]

Another run of the same apparatus is another file of the same kind: swap the path (and the
run's calibration). A file whose axes do not match its kind is refused with the reason.
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
from pathlib import Path

import numpy as np

from hertzchain.contact import kappa_sphere_flat, kappa_sphere_sphere
from hertzchain.driven import measurements as kinds
from hertzchain.driven.sweeper_files import (
    LockinSweep,
    SweeperFileError,
    SweeperTable,
    lockin_sweep,
    read_sweeper_table,
)
from hertzchain.io.importer import ExperimentFileError, quantity_of_key

KIND = "driven"
TOP_KEYS = ("kind", "label", "chain", "drive", "sensor", "sweep", "model", "measurement", "fit")
CHAIN_KEYS = ("n_beads", "bead_mass_kg", "bead_radius_m", "bead_youngs_pa", "bead_poisson", "face_youngs_pa",
              "face_poisson", "wall_youngs_pa", "wall_poisson", "precompression_n", "contact_kappa_n_m1p5")
DRIVE_KEYS = ("calibration_m_per_v", "calibration_uncertainty")
SENSOR_KEYS = ("bead", "quantity", "calibration_m_s_per_v", "reading")
SWEEP_KEYS = ("amplitude_file", "exclude_hz")
MODEL_KEYS = ("ramp_periods", "hold_periods", "window_periods", "steps_per_period")
_RUN_KEYS = ("kind", "run", "drive_calibration_m_per_v", "drive_calibration_uncertainty")
MEASUREMENT_KEYS = {
    "bending": _RUN_KEYS + ("amplitude_file", "exclude_hz"),
    "tongue": _RUN_KEYS + ("amplitude_file", "subharmonic_file"),
    "loop": _RUN_KEYS + ("amplitude_file", "subharmonic_file"),
    "scope": _RUN_KEYS + ("scope_file", "levels_file"),
}
FIT_KEYS = ("shared", "per_run")
MODEL_DEFAULTS = {"ramp_periods": 25, "hold_periods": 35, "window_periods": 4, "steps_per_period": 48}


# The sweeper's quantities (the file name's middle, `hertzchain.driven.sweeper_files`).
AMPLITUDE_QUANTITY = "Signal Amplitude_0"
QUANTITIES = {
    "Signal Amplitude_0": "the lock-in R at the drive frequency, V RMS",
    "Signal Phase_0": "the lock-in phase at the drive frequency, rad",
    "Signal Amplitude_3": "the lock-in R at half the drive frequency: the f/2 subharmonic",
    "Signal Phase_3": "the lock-in phase at half the drive frequency",
    "ScopeMaxAmplitude": "the scope record's maximum",
    "ScopePkToPk": "the scope record's peak-to-peak",
    "IntegratedPSDPower": "the total power of the scope record's spectrum",
    "DriveFreqPower": "the spectrum's power near the drive frequency",
    "DriveFreqNormalizedPower": "the share of the spectrum's power near the drive frequency",
}


class DrivenExperimentError(ExperimentFileError):
    """An experiment file that cannot be used; the message names the file, the key and the fix."""


@dataclasses.dataclass(frozen=True)
class DrivenExperiment:
    """A parsed driven experiment.

    **Fields:** `path`, `label`; `bead_mass_kg` (n,); `contact_kappa_n_m1p5` (n+1,) nominal
    Hertz constants (0 = face-bead 1, n = bead n-wall); `precompression_n` nominal;
    `drive_m_per_v` and its relative `drive_uncertainty`; `sensor_bead` (1-based), `quantity`;
    `sweep` (`LockinSweep`, SI); `fit_mask` (F,) False on excluded frequencies; `model`:
    the steady-state settings (`MODEL_KEYS`).
    """

    path: Path
    label: str
    bead_mass_kg: np.ndarray
    contact_kappa_n_m1p5: np.ndarray
    precompression_n: float
    drive_m_per_v: float
    drive_uncertainty: float
    sensor_bead: int
    quantity: str
    sweep: LockinSweep | None
    fit_mask: np.ndarray | None
    model: dict
    measurements: tuple = ()
    fit_options: dict = dataclasses.field(default_factory=dict)

    @property
    def n_beads(self) -> int:
        return int(self.bead_mass_kg.size)

    def for_bending(self, measurement: Measurement) -> DrivenExperiment:
        """This experiment with one bending `measurement` as its sweep (what `fitting.driven`
        fits), its run's drive calibration."""
        return dataclasses.replace(self, sweep=measurement.data.sweep, fit_mask=measurement.fit_mask,
                                   drive_m_per_v=measurement.drive_m_per_v,
                                   drive_uncertainty=measurement.drive_uncertainty, measurements=())


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One `[[measurement]]` of an experiment file: `kind`, `run`, `data` (a
    `hertzchain.driven.measurements` `Bending`, `Tongue`, `Loop` or `Scope`), the run's
    `drive_m_per_v` and relative `drive_uncertainty`, `fit_mask` (bending: False on excluded
    frequencies; None otherwise), `files` (the paths read)."""

    kind: str
    run: str
    data: object
    drive_m_per_v: float
    drive_uncertainty: float
    fit_mask: np.ndarray | None
    files: tuple


def is_driven_experiment(path) -> bool:
    """Whether `path` is a `.toml` experiment file with `kind = "driven"`.

    **Raises:** `DrivenExperimentError` for a file that is not UTF-8 text, or whose `kind` is not
    a kind of experiment (the message suggests the closest); an impact experiment has no `kind`.
    """
    path = Path(path)
    if path.suffix.lower() != ".toml" or not path.is_file():
        return False
    try:
        kind = tomllib.loads(path.read_text(encoding="utf-8")).get("kind")
    except tomllib.TOMLDecodeError:
        return False
    except UnicodeDecodeError:
        _fail(path, "not UTF-8 text; an experiment file is TOML, saved as UTF-8.")
    if kind is not None and kind != KIND:
        close = difflib.get_close_matches(str(kind), [KIND], n=1, cutoff=0.5)
        hint = f"did you mean kind = \"{close[0]}\"? " if close else ""
        _fail(path, f"kind = {kind!r} is not a kind of experiment; {hint}a driven experiment says kind = "
                    f"\"{KIND}\", an impact experiment (scope files of shots) has no kind key.")
    return kind == KIND


def _fail(where, message):
    raise DrivenExperimentError(f"{where}: {message}")


def _table(content: dict, name: str, keys, where: str, required=True) -> dict:
    table = content.get(name)
    if table is None:
        if required:
            _fail(where, f"missing table [{name}] (keys: {', '.join(keys)}).")
        return {}
    if not isinstance(table, dict):
        _fail(where, f"[{name}] must be a table.")
    for key in table:
        if key not in keys:
            _fail(f"{where} [{name}]", f"unknown key {key!r}; valid keys: {', '.join(keys)}.")
    return table


def _number(table: dict, key: str, where: str, default=None) -> float:
    """A number, or a string with a unit matching the key's suffix ("9.525mm" for *_m)."""
    if key not in table:
        if default is None:
            _fail(where, f"missing key {key!r}.")
        return float(default)
    return quantity_of_key(table[key], key, where)


def _positive(table, key, where, default=None) -> float:
    value = _number(table, key, where, default)
    if not (np.isfinite(value) and value > 0):
        _fail(where, f"{key} = {value!r} must be positive.")
    return value


def _contacts(chain: dict, n: int, where: str) -> np.ndarray:
    if "contact_kappa_n_m1p5" in chain:
        given = chain["contact_kappa_n_m1p5"]
        if not isinstance(given, list) or len(given) != n + 1:
            _fail(where, f"contact_kappa_n_m1p5 must list n_beads + 1 = {n + 1} Hertz constants (N/m^1.5), "
                         "face-bead 1 first, last bead-wall last.")
        kappa = np.array([_number({"k": v}, "k", where) for v in given])
        if np.any(kappa <= 0):
            _fail(where, "contact_kappa_n_m1p5 must all be positive.")
        return kappa
    radius = _positive(chain, "bead_radius_m", where)
    youngs = _positive(chain, "bead_youngs_pa", where)
    poisson = _number(chain, "bead_poisson", where)
    face = kappa_sphere_flat(radius, youngs, poisson, _positive(chain, "face_youngs_pa", where),
                             _number(chain, "face_poisson", where))
    wall = kappa_sphere_flat(radius, youngs, poisson, _positive(chain, "wall_youngs_pa", where),
                             _number(chain, "wall_poisson", where))
    between = kappa_sphere_sphere(radius, youngs, poisson, radius, youngs, poisson)
    return np.array([float(face)] + [float(between)] * (n - 1) + [float(wall)])


def _refuse_other_kinds(table: SweeperTable, where: str) -> None:
    """Refuse a sweeper file that is not a bending sweep's amplitude: a bending sweep varies the
    frequency (the row variable, swept fastest: `Frequency (Hz)`) at fixed drive amplitudes (the
    columns, V) and records the lock-in R at the drive frequency (`Signal Amplitude_0`). A
    period-doubling tongue varies the drive amplitude at fixed frequencies, beside a lock-in at f/2
    (`Signal Amplitude_3`); its file, read as a bending sweep, holds no resonance to fit."""
    if table.date and table.quantity.strip() != AMPLITUDE_QUANTITY:
        what = QUANTITIES.get(table.quantity.strip(), "not the lock-in amplitude at the drive frequency")
        _fail(where, f"{table.path.name}: the file holds {table.quantity.strip()!r} ({what}); amplitude_file "
                     f"is the sweeper's {AMPLITUDE_QUANTITY!r} file (the lock-in R at the drive frequency).")
    if table.row_unit != "Hz":
        fixed = table.column_values[0] if table.column_values.size == 1 else None
        at = (f"a fixed frequency of {fixed:g} Hz" if fixed is not None else
              f"{table.column_values.size} fixed frequencies, {table.column_values.min():g} to "
              f"{table.column_values.max():g} Hz") if table.column_unit == "Hz" else f"columns in {table.column_unit}"
        subharmonic = [p.name for p in table.path.parent.glob(f"{table.run} Signal Amplitude_3*")] if table.run else []
        beside = f" (beside it: {subharmonic[0]}, the lock-in at f/2 of a period-doubling run)" if subharmonic else ""
        _fail(where, f"{table.path.name} sweeps the {table.row_name.lower() or 'row variable'} ({table.row_unit}) at "
                     f"{at}{beside}: a drive-amplitude sweep such as a period-doubling tongue, not a bending sweep. "
                     "amplitude_file must sweep the frequency at fixed drive amplitudes (its first line "
                     "'Frequency (Hz)', then the drive voltages, e.g. 0.001V).")


def _read_sweep(sweep: dict, path, data_dir: Path, drive_m_per_v, sensor_m_s_per_v):
    """The `[sweep]` table's bending sweep and its fit mask."""
    where = f"{path} [sweep]"
    if "amplitude_file" not in sweep:
        _fail(where, "missing key 'amplitude_file' (the sweeper's 'Signal Amplitude_0' text file, "
                     "relative to --data-dir).")
    amplitude_file = data_dir / str(sweep["amplitude_file"])
    try:
        table = read_sweeper_table(amplitude_file)
        _refuse_other_kinds(table, where)
        measured = lockin_sweep(table, drive_m_per_v=drive_m_per_v, sensor_m_s_per_v=sensor_m_s_per_v)
    except SweeperFileError as error:
        if amplitude_file.is_file() and not amplitude_file.resolve().is_relative_to(data_dir.resolve()):
            # the reader's message may quote the file's lines: not of a file outside the folder named
            _fail(where, f"amplitude_file {amplitude_file} is not a sweeper text file; it lies outside --data-dir "
                         f"{data_dir}, so its content is not shown: check the path.")
        _fail(where, str(error))
    return measured, _exclusion_mask(measured.frequencies_hz, sweep.get("exclude_hz", []), where)


def _exclusion_mask(frequencies_hz, bands, where) -> np.ndarray:
    """False on the frequencies of `bands` ([low_hz, high_hz] pairs)."""
    mask = np.ones(frequencies_hz.size, bool)
    for band in bands:
        if not isinstance(band, list) or len(band) != 2 or not band[0] < band[1]:
            _fail(where, f"exclude_hz entry {band!r} must be [low_hz, high_hz] with low < high.")
        mask &= ~((frequencies_hz >= band[0]) & (frequencies_hz <= band[1]))
    if mask.sum() < 10:
        _fail(where, f"exclude_hz leaves {int(mask.sum())} frequencies; a fit needs at least 10.")
    return mask


def _file(table: dict, key: str, data_dir: Path, where: str) -> Path:
    if key not in table:
        _fail(where, f"missing key {key!r} (a file relative to --data-dir).")
    return data_dir / str(table[key])


def _read_measurement(table: dict, data_dir: Path, where: str, drive_m_per_v, sensor_m_s_per_v):
    """(data, fit mask or None, files) of one `[[measurement]]` table."""
    kind, run = table["kind"], str(table["run"])
    if kind == "bending":
        files = (_file(table, "amplitude_file", data_dir, where),)
        data = kinds.read_bending(files[0], run=run, drive_m_per_v=drive_m_per_v, sensor_m_s_per_v=sensor_m_s_per_v)
        return data, _exclusion_mask(data.sweep.frequencies_hz, table.get("exclude_hz", []), where), files
    if kind == "scope":
        files = (_file(table, "scope_file", data_dir, where), _file(table, "levels_file", data_dir, where))
        return kinds.read_scope(*files, run=run, drive_m_per_v=drive_m_per_v), None, files
    files = (_file(table, "amplitude_file", data_dir, where), _file(table, "subharmonic_file", data_dir, where))
    reader = kinds.read_tongue if kind == "tongue" else kinds.read_loop
    return reader(*files, run=run, drive_m_per_v=drive_m_per_v), None, files


def _read_measurements(tables, path, data_dir: Path, drive_m_per_v, uncertainty, sensor_m_s_per_v) -> tuple:
    """The `[[measurement]]` tables, read; a run's measurements must agree on its calibration."""
    if not isinstance(tables, list) or not tables:
        _fail(path, "measurement must be an array of tables: [[measurement]], one per measurement.")
    read, calibrations = [], {}
    for number, table in enumerate(tables, start=1):
        where = f"{path} [[measurement]] {number}"
        kind = table.get("kind")
        if kind not in MEASUREMENT_KEYS:
            close = difflib.get_close_matches(str(kind), list(MEASUREMENT_KEYS), n=1, cutoff=0.5)
            _fail(where, f"kind = {kind!r}; a measurement is one of {', '.join(MEASUREMENT_KEYS)}"
                         + (f" (did you mean {close[0]!r}?)" if close else "") + ".")
        for key in table:
            if key not in MEASUREMENT_KEYS[kind]:
                _fail(where, f"unknown key {key!r} for a {kind} measurement; valid keys: "
                             f"{', '.join(MEASUREMENT_KEYS[kind])}.")
        if not isinstance(table.get("run"), str) or not table["run"].strip():
            _fail(where, "missing key 'run': the run this measurement belongs to (e.g. its date and time); "
                         "measurements of one run share its precompression and drive calibration.")
        calibration = (_positive(table, "drive_calibration_m_per_v", where, default=drive_m_per_v),
                       _number(table, "drive_calibration_uncertainty", where, default=uncertainty))
        if not 0 <= calibration[1] < 1:
            _fail(where, f"drive_calibration_uncertainty = {calibration[1]!r} is relative; give 0 <= u < 1.")
        if calibrations.setdefault(table["run"], calibration) != calibration:
            _fail(where, f"run {table['run']!r} has another drive calibration in an earlier measurement "
                         f"({calibrations[table['run']]}): one run, one calibration.")
        try:
            data, mask, files = _read_measurement(table, data_dir, where, calibration[0], sensor_m_s_per_v)
        except SweeperFileError as error:
            outside = [f for f in _named_files(table, data_dir) if f.is_file()
                       and not f.resolve().is_relative_to(data_dir.resolve())]
            if outside:  # the reader's message may quote the file's lines: not of a file outside the folder
                _fail(where, f"{outside[0]} is not a {kind} file; it lies outside --data-dir {data_dir}, so its "
                             "content is not shown: check the path.")
            _fail(where, str(error))
        read.append(Measurement(kind, table["run"], data, calibration[0], calibration[1], mask,
                                tuple(str(f) for f in files)))
    return tuple(read)


def _named_files(table: dict, data_dir: Path) -> list:
    return [data_dir / str(v) for k, v in table.items() if k.endswith("_file")]


def _fit_options(table, path) -> dict:
    """The `[fit]` table: `shared` and `per_run` lists of parameter names (checked by the fit)."""
    if not isinstance(table, dict):
        _fail(path, "[fit] must be a table.")
    for key, value in table.items():
        if key not in FIT_KEYS:
            _fail(f"{path} [fit]", f"unknown key {key!r}; valid keys: {', '.join(FIT_KEYS)}.")
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            _fail(f"{path} [fit]", f"{key} must be a list of parameter names, e.g. [\"precompression_n\"].")
    return dict(table)


def load_driven_experiment(path, data_dir) -> DrivenExperiment:
    """Read and check a driven experiment file; sweep files are read from `data_dir`.

    **Raises:** `DrivenExperimentError` (a `ValueError`) naming the file, the key and the fix;
    `FileNotFoundError` when the file or `data_dir` is missing.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such experiment file: {path}")
    if data_dir is None:
        _fail(path, "the sweep files are relative to the data folder: give --data-dir DIR.")
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise FileNotFoundError(f"--data-dir {data_dir}: no such folder (it should hold the lab's sweep files).")
    try:
        content = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        _fail(path, f"not valid TOML ({error}).")
    for key in content:
        if key not in TOP_KEYS:
            _fail(path, f"unknown key or table {key!r}; valid: {', '.join(TOP_KEYS)}.")
    if content.get("kind") != KIND:
        _fail(path, f"kind = {content.get('kind')!r}; a driven experiment says kind = \"{KIND}\".")
    chain = _table(content, "chain", CHAIN_KEYS, path)
    drive = _table(content, "drive", DRIVE_KEYS, path)
    sensor = _table(content, "sensor", SENSOR_KEYS, path)
    sweep = _table(content, "sweep", SWEEP_KEYS, path, required=False)
    model = _table(content, "model", MODEL_KEYS, path, required=False)

    where = f"{path} [chain]"
    n = chain.get("n_beads")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        _fail(where, f"n_beads = {n!r} must be a positive integer.")
    masses = np.full(n, _positive(chain, "bead_mass_kg", where))
    kappa = _contacts(chain, n, where)
    precompression = _positive(chain, "precompression_n", where)

    where = f"{path} [drive]"
    drive_m_per_v = _positive(drive, "calibration_m_per_v", where)
    uncertainty = _number(drive, "calibration_uncertainty", where, default=0.0)
    if not 0 <= uncertainty < 1:
        _fail(where, f"calibration_uncertainty = {uncertainty!r} is relative (0.41 = 41 %); give 0 <= u < 1.")

    where = f"{path} [sensor]"
    bead = sensor.get("bead", 1)
    if isinstance(bead, bool) or not isinstance(bead, int) or not 1 <= bead <= n:
        _fail(where, f"bead = {bead!r}: the sensed bead, 1 (next to the drive) to n_beads = {n}.")
    quantity = str(sensor.get("quantity", "velocity"))
    if quantity != "velocity":
        _fail(where, f"quantity = {quantity!r}: only a vibrometer's \"velocity\" is supported.")
    reading = str(sensor.get("reading", "lockin_rms"))
    if reading != "lockin_rms":
        _fail(where, f"reading = {reading!r}: only \"lockin_rms\" (the lock-in's R) is supported.")
    sensor_m_s_per_v = _positive(sensor, "calibration_m_s_per_v", where)

    measured, mask, measurements = None, None, ()
    if ("sweep" in content) == ("measurement" in content):
        _fail(path, "give either a [sweep] table (one bending sweep) or [[measurement]] tables (every measurement, "
                    "each with its kind), not both" if "sweep" in content else
                    "missing table [sweep] (one bending sweep) or [[measurement]] tables (each with its kind: "
                    f"{', '.join(kinds.KINDS)}).")
    if "sweep" in content:
        measured, mask = _read_sweep(sweep, path, data_dir, drive_m_per_v, sensor_m_s_per_v)
    else:
        measurements = _read_measurements(content["measurement"], path, data_dir, drive_m_per_v, uncertainty,
                                          sensor_m_s_per_v)
    if "fit" in content and "sweep" in content:
        _fail(path, "[fit] (shared and per-run constants) is for files of [[measurement]] tables; a [sweep] "
                    "file is one run: leave [fit] out.")
    fit_options = _fit_options(content.get("fit", {}), path)

    settings = dict(MODEL_DEFAULTS)
    for key, value in model.items():
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            _fail(f"{path} [model]", f"{key} = {value!r} must be a positive integer.")
        settings[key] = value
    return DrivenExperiment(
        path=path, label=str(content.get("label", path.stem)), bead_mass_kg=masses, contact_kappa_n_m1p5=kappa,
        precompression_n=precompression, drive_m_per_v=drive_m_per_v, drive_uncertainty=uncertainty,
        sensor_bead=bead, quantity=quantity, sweep=measured, fit_mask=mask, model=settings,
        measurements=measurements, fit_options=fit_options,
    )
