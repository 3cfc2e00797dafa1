"""mkdocs hook: the reference page of experiment-file keys, `reference/experiment-files.md`,
made at build time from the key lists the readers check against (`hertzchain.io.importer`,
`hertzchain.io.tracefile`, `fitting.driven.experiment`), so that a key added to a reader without
a line here fails the build instead of going undocumented."""

from __future__ import annotations

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

# Meanings of the keys that are not trace-header keys (those carry their own, in
# `hertzchain.io.tracefile.HEADER_KEYS`).
IMPACT_MEANINGS = {
    "format": "file format of every file of the experiment: `auto` (from its first rows) or one of "
              "`hertzchain.io.scopefiles.FORMATS`",
    "time_zero": "`trigger`, a delay (`\"12us\"`), a trigger channel crossing a level (`\"channel:CH3>2.5V\"`), "
                 "optionally plus the delay from that crossing to the impact (`\"channel:CH3>2.5V+40us\"`)",
    "baseline_end_s": "end of the segment from which offsets and noise are taken, s [0: everything before the impact]",
    "source": "the scope's name of the channel (`CH1`, LeCroy `C2`, PicoScope `Channel A`)",
    "measures": "what the channel measures: `wall`, `contact_K` or `sensor_K`",
    "sensitivity_v_per_n": "sensitivity from the calibration sheet, V/N (0.1 mV/N to 10 V/N)",
    "coupling": "`ac` (reads changes of force since before the impact, as piezo sensors do) or `dc`",
    "noise_std_n": "noise standard deviation, N [estimated from the pre-trigger segment]",
    "offset_v": "DC offset, V [the mean of the pre-trigger segment]",
    "range_v": "the digitiser's limits `[low, high]`, V, when the file does not state them",
    "invert": "`true` for a sensor wired with the opposite sign",
    "sensor_beta": "embedded sensor's mass ratio β (Eq. 4)",
    "sensor_f0_hz": "embedded sensor's resonance, Hz",
    "files": "the shot's files, one per channel or one for all, relative to the experiment file",
    "label": "name of the shot in reports [the first file's stem]",
    "striker_velocity_m_s": "measured impact velocity, m/s [a fit's nuisance]",
    "nominal_velocity_m_s": "nominal impact velocity, m/s: shots at the same one are repeats",
}
DRIVEN_MEANINGS = {
    "kind": "`\"driven\"`: a driven experiment",
    "label": "name of the experiment in reports",
    "n_beads": "number of beads",
    "bead_mass_kg": "mass of one bead, kg",
    "bead_radius_m": "bead radius, m",
    "bead_youngs_pa": "bead Young's modulus, Pa",
    "bead_poisson": "bead Poisson ratio",
    "face_youngs_pa": "Young's modulus of the driven face (sphere-flat contact 0), Pa",
    "face_poisson": "Poisson ratio of the driven face",
    "wall_youngs_pa": "Young's modulus of the wall (sphere-flat contact n), Pa",
    "wall_poisson": "Poisson ratio of the wall",
    "precompression_n": "static precompression, N",
    "contact_kappa_n_m1p5": "the n + 1 Hertz constants, N/m^1.5, instead of the materials",
    "calibration_m_per_v": "piezo calibration, m of displacement per lock-in output volt",
    "calibration_uncertainty": "its relative uncertainty (1 σ)",
    "bead": "the bead read (1 = next to the driven face)",
    "quantity": "`velocity` or `displacement`",
    "calibration_m_s_per_v": "vibrometer calibration, (m/s) per volt",
    "reading": "`lockin_rms`: the lock-in's R, the RMS at the drive frequency",
    "amplitude_file": "the sweeper's amplitude file, relative to `--data-dir`",
    "exclude_hz": "frequency bands `[[low, high], ...]` left out of fits, Hz",
    "ramp_periods": "drive periods of the amplitude ramp",
    "hold_periods": "periods held at full amplitude before the lock-in window",
    "window_periods": "whole periods the lock-in integrates",
    "steps_per_period": "Verlet steps per drive period",
}


def _row(key: str, meaning: str, required: str = "") -> str:
    return f"| `{key}` | {required} | {meaning.replace('|', '/')} |"


def _table(keys, meanings, where: str, header_keys=None) -> str:
    rows = ["| key | required | meaning (unit) |", "|---|---|---|"]
    for key in keys:
        spec = (header_keys or {}).get(key)
        if spec is not None and key not in meanings:
            rows.append(_row(key, spec.meaning, "yes" if spec.required else ""))
        elif key in meanings:
            rows.append(_row(key, meanings[key]))
        else:
            raise PluginError(f"experiment-file key {key!r} of {where} has no meaning in "
                              "docs/hooks/experiment_keys.py: add one")
    return "\n".join(rows)


def page() -> str:
    from fitting.driven import experiment as driven
    from hertzchain.io import importer, tracefile

    return "\n\n".join([
        "# Experiment-file keys",
        "Every key an experiment file may hold, read from the lists the readers check against "
        "(an unknown key is an error that names the valid ones). Quantities with a plain SI unit "
        "may be written with a unit as a string (`bead_radius_m = \"13mm\"`, `wall_youngs_pa = "
        "\"5GPa\"`). How to write one: [Experiment files](../how-to/experiment-files.md).",
        "## Impact experiments",
        "Tables `[chain]`, `[scope]`, `[[channel]]` (one per channel), `[[shot]]` (one per shot) and "
        "the optional `[prior]` (the lab's tolerances, in the syntax of `--prior`: "
        "`bead_youngs = \"203GPa+-4GPa\"`).",
        "### `[chain]`",
        "The chain, as a trace file's header holds it (`hertzchain.io.tracefile`); a `[[shot]]` may "
        "repeat any of these keys for itself.",
        _table(importer.CHAIN_KEYS, {}, "[chain]", tracefile.HEADER_KEYS),
        "### `[scope]`",
        _table(importer.SCOPE_KEYS, IMPACT_MEANINGS, "[scope]"),
        "### `[[channel]]`",
        _table(importer.CHANNEL_KEYS, IMPACT_MEANINGS, "[[channel]]"),
        "### `[[shot]]`",
        _table([k for k in importer.SHOT_KEYS if k not in importer.CHAIN_KEYS], IMPACT_MEANINGS, "[[shot]]"),
        "## Driven experiments",
        "`kind = \"driven\"` and `label` at the top, then `[chain]`, `[drive]`, `[sensor]`, `[sweep]` "
        "and `[model]`. Paths are relative to the folder given as `--data-dir`.",
        "### Top level",
        _table([k for k in driven.TOP_KEYS if k in ("kind", "label")], DRIVEN_MEANINGS, "top level"),
        "### `[chain]`", _table(driven.CHAIN_KEYS, DRIVEN_MEANINGS, "[chain]"),
        "### `[drive]`", _table(driven.DRIVE_KEYS, DRIVEN_MEANINGS, "[drive]"),
        "### `[sensor]`", _table(driven.SENSOR_KEYS, DRIVEN_MEANINGS, "[sensor]"),
        "### `[sweep]`", _table(driven.SWEEP_KEYS, DRIVEN_MEANINGS, "[sweep]"),
        "### `[model]`", _table(driven.MODEL_KEYS, DRIVEN_MEANINGS, "[model]"),
    ]) + "\n"


def on_files(files, config):
    files.append(File.generated(config, "reference/experiment-files.md", content=page()))
    return files
