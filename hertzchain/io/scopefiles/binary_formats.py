"""Readers of the array and binary scope formats: NumPy .npz, MATLAB .mat, Tektronix .isf
and Rigol .wfm."""

from __future__ import annotations

import gc
import re
import warnings
from pathlib import Path

import numpy as np

from .common import (
    TIME_NAMES,
    ScopeFileError,
    Waveforms,
    _check_time,
    _check_values,
    _stem_channel_name,
)

# --- npz and mat --------------------------------------------------------------------------

def _from_arrays(path: Path, format: str, arrays: dict[str, np.ndarray], rename) -> Waveforms:
    """Waveforms from named arrays: a time array (`TIME_NAMES`), channels, `<name>_range_v`."""
    found = [k for k in TIME_NAMES if k in arrays]
    if not found:
        raise ScopeFileError(f"{path}: no time array; name it one of {', '.join(TIME_NAMES)} (seconds). "
                             f"The file holds: {', '.join(arrays) or 'nothing'}.")
    if len(found) > 1:
        raise ScopeFileError(f"{path}: several time arrays ({', '.join(found)}); keep one.")
    time_s = np.asarray(arrays[found[0]]).squeeze()
    if time_s.ndim != 1 or not np.issubdtype(time_s.dtype, np.number):
        raise ScopeFileError(f"{path}: key {found[0]!r} has shape {time_s.shape}; time must be a 1-D "
                             f"numeric vector.")
    time_s = time_s.astype(np.float64)
    _check_time(path, time_s, what="sample")
    channels: dict[str, np.ndarray] = {}
    ranges: dict[str, np.ndarray] = {}
    info: dict[str, str] = {"time": found[0]}
    for key, raw in arrays.items():
        if key == found[0]:
            continue
        array = np.asarray(raw)
        if key.endswith("_range_v"):
            ranges[key[: -len("_range_v")]] = array
            continue
        if not np.issubdtype(array.dtype, np.number) or array.size == 1:
            info[key] = str(array.squeeze()) if array.size <= 16 else f"<{array.dtype} {array.shape}>"
            continue
        values = array.squeeze()
        if values.ndim != 1:
            raise ScopeFileError(f"{path}: key {key!r} has shape {array.shape}; a channel must be a "
                                 f"vector of {time_s.size} values.")
        name = rename(key)
        if name in channels:
            raise ScopeFileError(f"{path}: keys name channel {name!r} twice; rename one.")
        values = values.astype(np.float64)
        _check_values(path, name, values, time_s.size)
        channels[name] = values
    if not channels:
        raise ScopeFileError(f"{path}: no channel arrays besides {found[0]!r}; the file holds: "
                             f"{', '.join(arrays)}.")
    range_v: dict[str, tuple[float, float] | None] = dict.fromkeys(channels)
    for name, limits in ranges.items():
        channel = rename(name)
        limits = np.asarray(limits, dtype=np.float64).ravel()
        if channel not in channels:
            raise ScopeFileError(f"{path}: key {name}_range_v names no channel; channels: {', '.join(channels)}.")
        if limits.size != 2 or not limits[0] < limits[1]:
            raise ScopeFileError(f"{path}: key {name}_range_v = {limits}; give [low, high] in volts, low < high.")
        range_v[channel] = (float(limits[0]), float(limits[1]))
    return Waveforms(str(path), format, time_s, channels, range_v, dict.fromkeys(channels), info)


def _read_npz(path: Path) -> Waveforms:
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (ValueError, OSError) as error:
        raise ScopeFileError(f"{path}: not a readable .npz ({error}); save it with numpy.savez.") from None
    return _from_arrays(path, "npz", arrays, lambda key: key)


def _read_mat(path: Path) -> Waveforms:
    import scipy.io

    try:
        contents = scipy.io.loadmat(path)
    except NotImplementedError:
        raise ScopeFileError(f"{path}: a MATLAB v7.3 (HDF5) file, which is not supported; save it as "
                             f"v7 in MATLAB: save('{path.name}', ..., '-v7').") from None
    except (ValueError, OSError, TypeError) as error:
        raise ScopeFileError(f"{path}: not a readable .mat file ({error}).") from None
    arrays = {k: v for k, v in contents.items() if not k.startswith("__")}

    def rename(key: str) -> str:
        if re.fullmatch(r"ch\d+", key, flags=re.IGNORECASE):
            return key.upper()
        return _stem_channel_name(path) if key == "y" else key

    return _from_arrays(path, "mat", arrays, rename)


# --- tek-isf ------------------------------------------------------------------------------

_ISFREADER_FIELDS = ("VSCALE", "HSCALE", "VPOS", "VOFFSET", "HDELAY")


def _read_tek_isf(path: Path) -> Waveforms:
    import isfreader

    data = path.read_bytes()
    try:
        header, block = isfreader.split_isf_header(data)
    except isfreader.py_isfreader.InvalidFileError as error:
        preamble = data.split(b":CURV", 1)[0].decode("latin-1")
        missing = [k for k in _ISFREADER_FIELDS if not re.search(rf"[:;]{k} ", preamble)]
        hint = (f"its header lacks {', '.join(missing)}, which isfreader requires; save the record as "
                f"CSV (format 'tek-csv') instead" if missing else "check that it is a Tektronix .isf file")
        raise ScopeFileError(f"{path}: isfreader cannot read it ({error}); {hint}.") from None
    except (ValueError, IndexError) as error:
        raise ScopeFileError(f"{path}: not a Tektronix .isf file ({error}); it needs a header "
                             f"':WFMPRE:...;:CURVE #<n><length><data>'.") from None
    info = {key: str(value) for key, value in header.items()}
    if not str(header["ENCDG"]).upper().startswith("BIN"):
        raise ScopeFileError(f"{path}: ENCDG {header['ENCDG']}; only binary curves are read, save the "
                             f"record with binary encoding or as CSV.")
    if str(header["PT_FMT"]).upper() != "Y":
        raise ScopeFileError(f"{path}: PT_FMT {header['PT_FMT']}; only sampled records (PT_FMT Y) are "
                             f"read, not envelopes; acquire in Sample mode.")
    if header["XUNIT"].lower() != "s" or header["YUNIT"] != "V":
        raise ScopeFileError(f"{path}: XUNIT {header['XUNIT']!r}, YUNIT {header['YUNIT']!r}; a time record "
                             f"in volts needs XUNIT \"s\" and YUNIT \"V\".")
    width = header["BYT_NR"]
    signed = str(header["BN_FMT"]).upper() == "RI"
    dtype = np.dtype(f"{'>' if header['BYT_OR'] == 'MSB' else '<'}{'i' if signed else 'u'}{width}")
    if len(block) != header["NR_PT"] * width:
        raise ScopeFileError(f"{path}: the curve block has {len(block)} bytes but NR_PT {header['NR_PT']} x "
                             f"BYT_NR {width} = {header['NR_PT'] * width}; the file is truncated.")
    codes = np.frombuffer(block, dtype=dtype).astype(np.float64)
    ymult, yoff, yzero = header["YMULT"], header["YOFF"], header["YZERO"]
    volts = (codes - yoff) * ymult + yzero
    time_s = (np.arange(codes.size) - header["PT_OFF"]) * header["XINCR"] + header["XZERO"]
    _check_time(path, time_s, what="sample")
    match = re.match(r"(CH\d+|MATH|REF\w)", str(header["WFID"]).strip('" '), flags=re.IGNORECASE)
    name = match.group(1).upper() if match else _stem_channel_name(path)
    bits = 8 * width
    low_code, high_code = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    limits = sorted(((low_code - yoff) * ymult + yzero, (high_code - yoff) * ymult + yzero))
    lsb = abs(ymult) * (256 if width == 2 and np.all(codes % 256 == 0) else 1)
    return Waveforms(str(path), "tek-isf", time_s, {name: volts}, {name: (limits[0], limits[1])},
                     {name: float(lsb)}, info)


# --- rigol-wfm ----------------------------------------------------------------------------

def _read_rigol_wfm(path: Path) -> Waveforms:
    # RigolWFM's Kaitai parsers leave the file open inside the parsed record (a reference
    # cycle): the record is read and dropped, and collected, with that ResourceWarning muted.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        waves = _rigol_waveforms(path)
        gc.collect()
    return waves


def _rigol_waveforms(path: Path) -> Waveforms:
    import RigolWFM.wfm as rigol

    try:
        record = rigol.Wfm.from_file(str(path))
    except Exception as error:  # noqa: BLE001 - RigolWFM raises its own classes, struct and Kaitai errors
        raise ScopeFileError(f"{path}: RigolWFM cannot read it ({type(error).__name__}: {error}); check "
                             f"that it is a .wfm saved by a Rigol scope that RigolWFM supports.") from None
    if not record.channels:
        raise ScopeFileError(f"{path}: RigolWFM finds no enabled channel in it.")
    time_s = np.asarray(record.channels[0].times, dtype=np.float64)
    _check_time(path, time_s, what="sample")
    channels, lsb_v = {}, {}
    info = {"model": str(record.header_name), "parser": str(record.parser_name),
            "serial_number": str(record.serial_number)}
    for channel in record.channels:
        name = channel.name.replace(" ", "").upper()
        if not np.array_equal(np.asarray(channel.times, dtype=np.float64), time_s):
            raise ScopeFileError(f"{path}: channel {name} has another time grid than "
                                 f"{record.channels[0].name}; RigolWFM reads them apart.")
        volts = np.asarray(channel.volts, dtype=np.float64)
        _check_values(path, name, volts, time_s.size)
        channels[name] = volts
        lsb_v[name] = _rigol_step(channel.raw, volts)
        for key in ("volt_per_division", "volt_offset", "probe_value", "coupling"):
            info[f"{name} {key}"] = str(getattr(channel, key))
    return Waveforms(str(path), "rigol-wfm", time_s, channels, dict.fromkeys(channels), lsb_v, info)


def _rigol_step(raw, volts: np.ndarray) -> float | None:
    """Volts per raw code of the linear map from `raw` to `volts`, or None if there is none."""
    if raw is None:
        return None
    raw = np.asarray(raw, dtype=np.float64)
    if raw.shape != volts.shape or np.ptp(raw) == 0:
        return None
    i, j = int(np.argmin(raw)), int(np.argmax(raw))
    slope = (volts[j] - volts[i]) / (raw[j] - raw[i])
    linear = np.allclose(volts, volts[i] + slope * (raw - raw[i]), rtol=0, atol=1e-6 * abs(slope))
    return float(abs(slope)) if linear else None
