"""Scope file readers: files written by other writers (csv module, numpy.savez, scipy.io.savemat,
raw bytes) from known arrays, read back and compared to the precision each format stores."""

import csv
import struct
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hertzchain.io.scopefiles import (
    FORMATS,
    ScopeFileError,
    detect_format,
    merge_waveforms,
    read_waveforms,
)

DATA = Path(__file__).parent / "data"


def pulse_v(time_s, offset_v=0.3, amplitude_v=2.0, width_s=2e-3):
    """A cos^6 pulse centred at 1 ms on an offset (V)."""
    phase = np.clip((time_s - 1e-3) / width_s, -0.5, 0.5) * np.pi
    return offset_v + amplitude_v * np.cos(phase) ** 6


def tds_record(lsb_v, position_v, n=500, dt_s=1e-5, pre=100):
    """Time (s) and the 8-bit TDS values (V): code = value / lsb + YOFF, codes -128..127."""
    time_s = (np.arange(n) - pre) * dt_s
    codes = np.clip(np.round((pulse_v(time_s) + position_v) / lsb_v), -128, 127)
    return time_s, codes * lsb_v - position_v


def write_tek_csv(path, time_s, volts, settings, value_scale=1.0):
    """The TDS1000/2000 layout: 6 columns, settings in 1-2, time and value in 4-5, CRLF."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\r\n")
        for k, (t, v) in enumerate(zip(time_s, volts)):
            key, value = settings[k] if k < len(settings) else ("", "")
            writer.writerow([key, value, "", f"{t:.9e}", f"{v * value_scale:.6e}", ""])


TDS_SETTINGS = [("Record Length", "5.000000e+02"), ("Sample Interval", "1.000000e-05"),
                ("Trigger Point", "1.000000000000e+02"), ("Trigger Time", "0.000000e+00"), ("", ""),
                ("Source", "CH1"), ("Vertical Units", "mV"), ("Vertical Scale", "5.000000e+02"),
                ("Vertical Offset", "-1.000000e+03"), ("Horizontal Units", "s"),
                ("Horizontal Scale", "5.000000e-04"), ("Pt Fmt", "Y"), ("Yzero", "0.000000e+00"),
                ("Probe Atten", "1.000000e+00"), ("Model Number", "TDS2024B"),
                ("Serial Number", "C012345"), ("Firmware Version", "FV:v22.11"), ("", "")]


def test_tek_csv_values_units_lsb_and_range(tmp_path):
    # 500 mV/div -> 20 mV per code; Vertical Offset -1000 mV = position, YOFF = -50 codes.
    time_s, volts = tds_record(lsb_v=0.02, position_v=-1.0)
    path = tmp_path / "F0000CH1.CSV"
    write_tek_csv(path, time_s, volts, TDS_SETTINGS, value_scale=1e3)
    assert detect_format(path) == "tek-csv"
    waves = read_waveforms(path)
    assert waves.format == "tek-csv" and list(waves.channels) == ["CH1"]
    np.testing.assert_allclose(waves.time_s, time_s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(waves.channels["CH1"], volts, rtol=1e-6, atol=1e-9)
    assert waves.lsb_v["CH1"] == pytest.approx(0.02, rel=1e-12)
    low, high = waves.range_v["CH1"]
    assert (low, high) == pytest.approx((-128 * 0.02 + 1.0, 127 * 0.02 + 1.0), rel=1e-12)
    assert waves.info["Model Number"] == "TDS2024B" and waves.info["Vertical Units"] == "mV"
    assert waves.channels["CH1"].dtype == np.float64


def test_tek_csv_without_source_is_named_by_stem_and_guards_range(tmp_path):
    time_s, volts = tds_record(lsb_v=0.04, position_v=0.0)
    settings = [s for s in TDS_SETTINGS if s[0] not in ("Source", "Vertical Units")]
    settings = [s if s[0] != "Vertical Scale" else ("Vertical Scale", "1.0e+00") for s in settings]
    # A wrong-sign offset puts the samples outside the implied range: range_v is then unknown.
    settings = [s if s[0] != "Vertical Offset" else ("Vertical Offset", "3.0e+00") for s in settings]
    write_tek_csv(tmp_path / "F0003CH2.CSV", time_s, volts, settings)
    waves = read_waveforms(tmp_path / "F0003CH2.CSV", "tek-csv")
    assert list(waves.channels) == ["CH2"] and waves.lsb_v["CH2"] == pytest.approx(0.04)
    np.testing.assert_allclose(waves.channels["CH2"], volts, rtol=1e-6, atol=1e-9)
    assert waves.range_v["CH2"] is None and "outside" in waves.info["range_v"]
    write_tek_csv(tmp_path / "shot7.csv", time_s, volts, settings)
    assert list(read_waveforms(tmp_path / "shot7.csv").channels) == ["shot7"]


def test_tek_csv_record_length_and_bad_cell(tmp_path):
    time_s, volts = tds_record(lsb_v=0.02, position_v=0.0)
    write_tek_csv(tmp_path / "a.csv", time_s[:-3], volts[:-3], TDS_SETTINGS)
    with pytest.raises(ScopeFileError, match=r"a\.csv: Record Length says 500 points but the file has 497"):
        read_waveforms(tmp_path / "a.csv")
    text = (tmp_path / "a.csv").read_text().splitlines()
    text[30] = ",,,1.0e-4,,"
    (tmp_path / "b.csv").write_text("\n".join(text))
    with pytest.raises(ScopeFileError, match=r"b\.csv: row 31, column 5 \(value\): empty cell"):
        read_waveforms(tmp_path / "b.csv")


def write_generic(path, header, rows, comments=()):
    with open(path, "w", newline="") as handle:
        handle.writelines(line + "\n" for line in comments)
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)


def test_generic_csv_units_and_comments(tmp_path):
    time_s = np.arange(-50, 200) * 2e-6
    ch1_v, wall_v = pulse_v(time_s, width_s=2e-4), 0.5 * pulse_v(time_s, offset_v=-0.1, width_s=3e-4)
    rows = [[f"{t * 1e3:.9g}", f"{a * 1e3:.9g}", f"{b:.9g}"] for t, a, b in zip(time_s, ch1_v, wall_v)]
    path = tmp_path / "shot.csv"
    write_generic(path, ["time (ms)", "CH1 (mV)", "wall [V]"], rows, comments=["# shot 3", "# 20 C"])
    assert detect_format(path) == "csv"
    waves = read_waveforms(path)
    assert list(waves.channels) == ["CH1", "wall"]
    np.testing.assert_allclose(waves.time_s, time_s, rtol=1e-8, atol=1e-15)
    np.testing.assert_allclose(waves.channels["CH1"], ch1_v, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(waves.channels["wall"], wall_v, rtol=1e-8, atol=1e-12)
    assert waves.range_v == {"CH1": None, "wall": None} and waves.lsb_v["CH1"] is None
    write_generic(tmp_path / "u.csv", ["time_us", "CH1_uV", "piezo"],
                  [[f"{t * 1e6:.9g}", f"{a * 1e6:.9g}", f"{b:.9g}"] for t, a, b in zip(time_s, ch1_v, wall_v)])
    waves = read_waveforms(tmp_path / "u.csv", "csv")
    np.testing.assert_allclose(waves.time_s, time_s, rtol=1e-8, atol=1e-15)
    np.testing.assert_allclose(waves.channels["CH1"], ch1_v, rtol=1e-8)
    np.testing.assert_allclose(waves.channels["piezo"], wall_v, rtol=1e-8)


@pytest.mark.parametrize("header, rows, message", [
    (["time (s)", "CH1 (V)"], [["0", "1"], ["1e-6", "x1"]], r"row 3, column 2 \(CH1 \(V\)\): 'x1' is not a number"),
    (["time (s)", "CH1 (V)"], [["0", "1"], ["1e-6", "nan"]], r"row 3, column 2 \(CH1 \(V\)\): 'nan'"),
    (["time (s)", "CH1 (V)"], [["0", "1"], ["1e-6", ""]], r"row 3, column 2 \(CH1 \(V\)\): empty cell"),
    (["time (s)", "CH1 (furlong)"], [["0", "1"]], r"unknown unit 'furlong'; known units: V, mV, uV"),
    (["time (min)", "CH1"], [["0", "1"]], r"unknown unit 'min'; known units: s, ms, us"),
    (["time (s)", "CH1 (V)"], [["0", "1"], ["2e-6", "1"], ["1e-6", "1"]], r"row 4: time 1e-06 s does not increase"),
    (["time (s)", "CH1 (V)", "CH2 (V)"], [["0", "1", "2"], ["1e-6", "1"]], r"row 3 has 2 cells and the header 3"),
])
def test_generic_csv_errors(tmp_path, header, rows, message):
    write_generic(tmp_path / "bad.csv", header, rows)
    with pytest.raises(ScopeFileError, match=r"bad\.csv: .*" + message):
        read_waveforms(tmp_path / "bad.csv")


def test_npz_channels_and_range(tmp_path):
    time_s = np.arange(-20, 300) * 1e-6
    codes = np.round(pulse_v(time_s, width_s=2e-4) / 0.01)
    np.savez(tmp_path / "r.npz", time_s=time_s, CH1=codes * 0.01, CH2=-codes * 0.02,
             CH1_range_v=np.array([-1.28, 1.27]), gain=np.array(10.0))
    waves = read_waveforms(tmp_path / "r.npz")
    assert waves.format == "npz" and list(waves.channels) == ["CH1", "CH2"]
    np.testing.assert_array_equal(waves.time_s, time_s)
    np.testing.assert_array_equal(waves.channels["CH2"], -codes * 0.02)
    assert waves.range_v == {"CH1": (-1.28, 1.27), "CH2": None} and waves.info["gain"] == "10.0"
    np.savez(tmp_path / "n.npz", seconds=time_s, CH1=codes)
    with pytest.raises(ScopeFileError, match=r"n\.npz: no time array; name it one of time_s, t, time .*holds: seconds, CH1"):
        read_waveforms(tmp_path / "n.npz")
    np.savez(tmp_path / "l.npz", t=time_s, CH1=codes[:-1])
    with pytest.raises(ScopeFileError, match=r"l\.npz: channel 'CH1' has 319 values and time has 320"):
        read_waveforms(tmp_path / "l.npz")


def test_mat_tek_style_vectors_and_v73(tmp_path):
    time_s = np.arange(-10, 200) * 5e-7
    ch1_v = pulse_v(time_s, width_s=5e-5)
    scipy.io.savemat(tmp_path / "scope.mat", {"t": time_s[:, None], "ch1": ch1_v[None, :], "ch2": 2 * ch1_v,
                                              "wall_range_v": [-5.0, 5.0], "wall": -ch1_v})
    waves = read_waveforms(tmp_path / "scope.mat")
    assert waves.format == "mat" and sorted(waves.channels) == ["CH1", "CH2", "wall"]
    np.testing.assert_array_equal(waves.time_s, time_s)
    np.testing.assert_array_equal(waves.channels["CH1"], ch1_v)
    np.testing.assert_array_equal(waves.channels["wall"], -ch1_v)
    assert waves.range_v["wall"] == (-5.0, 5.0) and waves.range_v["CH1"] is None
    scipy.io.savemat(tmp_path / "F0001CH3.mat", {"time": time_s, "y": ch1_v})
    assert list(read_waveforms(tmp_path / "F0001CH3.mat").channels) == ["CH3"]
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(116, b" ")
    (tmp_path / "big.mat").write_bytes(header + bytes(8) + b"\x00\x02IM" + bytes(512))
    with pytest.raises(ScopeFileError, match=r"big\.mat: a MATLAB v7\.3 \(HDF5\) file.*'-v7'"):
        read_waveforms(tmp_path / "big.mat")


def isf_bytes(codes, ymult, yoff, xincr, xzero, extra=True, width=2):
    """A TDS-style ISF file, byte by byte: preamble, ':CURVE #<n><len>', big-endian codes."""
    fields = [f"BYT_NR {width}", f"BIT_NR {8 * width}", "ENCDG BIN", "BN_FMT RI", "BYT_OR MSB",
              f"NR_PT {len(codes)}",
              'WFID "Ch2, DC coupling, 5.0E-1 V/div, 5.0E-4 s/div, 2500 points, Sample mode"',
              "PT_FMT Y", f"XINCR {xincr:.6E}", "PT_OFF 0", f"XZERO {xzero:.6E}", 'XUNIT "s"',
              f"YMULT {ymult:.6E}", "YZERO 0.0E0", f"YOFF {yoff:.6E}", 'YUNIT "V"']
    if extra:
        fields += ["VSCALE 5.0E-1", "HSCALE 5.0E-4", "VPOS -2.0E0", "VOFFSET 0.0E0", "HDELAY 0.0E0"]
    block = struct.pack(f">{len(codes)}{'h' if width == 2 else 'b'}", *(int(c) for c in codes))
    size = str(len(block)).encode()
    return (":WFMPRE:" + ";".join(fields) + ";:CURVE #").encode() + str(len(size)).encode() + size + block + b"\n"


def test_tek_isf_codes_times_lsb_and_range(tmp_path):
    # 0.5 V/div: 8-bit step 0.02 V, sent at width 2 as code*256 (YMULT = 0.02/256); position -2 div.
    n, xincr, xzero = 2500, 2e-6, -1e-3
    time_s = np.arange(n) * xincr + xzero
    yoff = -50 * 256
    codes8 = np.clip(np.round(pulse_v(time_s) / 0.02) - 50, -128, 127)
    path = tmp_path / "TEK0001.ISF"
    path.write_bytes(isf_bytes(codes8 * 256, 0.02 / 256, yoff, xincr, xzero))
    assert detect_format(path) == "tek-isf"
    waves = read_waveforms(path)
    assert list(waves.channels) == ["CH2"]
    np.testing.assert_allclose(waves.time_s, time_s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(waves.channels["CH2"], (codes8 + 50) * 0.02, rtol=0, atol=1e-12)
    assert waves.lsb_v["CH2"] == pytest.approx(0.02, rel=1e-12)
    assert waves.range_v["CH2"] == pytest.approx(((-32768 - yoff) * 0.02 / 256, (32767 - yoff) * 0.02 / 256))
    assert waves.info["YMULT"] == repr(0.02 / 256) and waves.info["NR_PT"] == "2500"
    path.write_bytes(isf_bytes(np.arange(-100, 100), 0.04, 0.0, 1e-6, 0.0, width=1))
    waves = read_waveforms(path, "tek-isf")
    np.testing.assert_allclose(waves.channels["CH2"], np.arange(-100, 100) * 0.04, rtol=0, atol=1e-12)
    assert waves.lsb_v["CH2"] == pytest.approx(0.04) and waves.range_v["CH2"] == pytest.approx((-5.12, 5.08))
    path.write_bytes(isf_bytes(np.arange(10), 0.04, 0.0, 1e-6, 0.0, extra=False))
    with pytest.raises(ScopeFileError, match=r"TEK0001\.ISF: .*lacks VSCALE, HSCALE, VPOS, VOFFSET, HDELAY"):
        read_waveforms(path)


def test_rigol_wfm_against_rigolwfm_snapshot():
    # Values from RigolWFM's tests/expected_info/d/DS1102D-A.txt (see tests/data/README.md).
    waves = read_waveforms(DATA / "DS1102D-A.wfm")
    assert waves.format == "rigol-wfm" and list(waves.channels) == ["CH1", "CH2"]
    assert waves.time_s.size == 1024
    assert waves.time_s[[0, 1, -1]] == pytest.approx([-4.688e-3, -4.678e-3, 5.542e-3], abs=1e-9)
    assert waves.channels["CH1"][[0, -1]] == pytest.approx([0.16, 4.80], abs=1e-9)
    assert waves.channels["CH2"][[0, -1]] == pytest.approx([2.96, 0.0], abs=1e-9)
    assert waves.lsb_v == pytest.approx({"CH1": 1.0 / 25, "CH2": 2.0 / 25})
    assert waves.range_v == {"CH1": None, "CH2": None}


def test_rigol_wfm_unreadable(tmp_path):
    (tmp_path / "junk.wfm").write_bytes(b"\x01\x02not a scope file" * 8)
    with pytest.raises(ScopeFileError, match=r"junk\.wfm: RigolWFM cannot read it"):
        read_waveforms(tmp_path / "junk.wfm")


def test_general_errors(tmp_path):
    with pytest.raises(ScopeFileError, match=r"unknown format 'lecroy'; use 'auto' or one of: tek-csv \("):
        read_waveforms(tmp_path / "x.csv", "lecroy")
    with pytest.raises(ScopeFileError, match=r"missing\.csv: no such file"):
        read_waveforms(tmp_path / "missing.csv")
    (tmp_path / "empty.csv").write_bytes(b"")
    with pytest.raises(ScopeFileError, match=r"empty\.csv: the file is empty"):
        read_waveforms(tmp_path / "empty.csv")
    (tmp_path / "x.dat").write_text("1,2\n")
    with pytest.raises(ScopeFileError, match=r"x\.dat: unknown suffix '\.dat'.*" + "; ".join(FORMATS)[:7]):
        detect_format(tmp_path / "x.dat")


def test_merge(tmp_path):
    time_s = np.arange(100) * 1e-6 - 2e-5
    np.savez(tmp_path / "a.npz", time_s=time_s, CH1=np.sin(time_s * 1e5))
    np.savez(tmp_path / "b.npz", time_s=time_s + 1e-18, CH2=np.cos(time_s * 1e5))
    a, b = read_waveforms(tmp_path / "a.npz"), read_waveforms(tmp_path / "b.npz")
    merged = merge_waveforms([a, b], "shot 1")
    assert list(merged.channels) == ["CH1", "CH2"] and merged.format == "npz"
    np.testing.assert_array_equal(merged.channels["CH2"], np.cos(time_s * 1e5))
    np.savez(tmp_path / "c.npz", time_s=time_s[:-1], CH3=time_s[:-1])
    np.savez(tmp_path / "d.npz", time_s=time_s + 1e-7, CH3=time_s)
    np.savez(tmp_path / "e.npz", time_s=(time_s - time_s[0]) * 1.001 + time_s[0], CH3=time_s)
    cases = [("c", r"shot 1: .*a\.npz has 100 samples and .*c\.npz has 99"),
             ("d", r"shot 1: first times differ: -2e-05 s in .*a\.npz, -1\.9[0-9]*e-05 s in .*d\.npz"),
             ("e", r"shot 1: sample intervals differ: 1e-06 s in .*a\.npz, 1\.00(1|09)[0-9]*e-06 s in .*e\.npz"),
             ("a", r"shot 1: channel 'CH1' is in both .*a\.npz and .*a\.npz")]
    for name, message in cases:
        with pytest.raises(ScopeFileError, match=message):
            merge_waveforms([a, read_waveforms(tmp_path / f"{name}.npz")], "shot 1")


# --- vendor CSV exports, each written by the csv module or as plain text ------------------

def vendor_record(n=400, dt_s=2e-6, pre=80):
    """Time (s) and two channels (V) on an 8-bit-like lattice, and a TTL light gate."""
    time_s = (np.arange(n) - pre) * dt_s
    lsb = 0.0016
    ch1 = np.round(pulse_v(time_s * 5.0, offset_v=0.01, amplitude_v=0.3) / lsb) * lsb
    ch3 = np.where(time_s >= -40e-6, 5.0, 0.0) + np.round(0.02 * np.sin(time_s * 1e5) / 0.04) * 0.04
    return time_s, {"CH1": ch1, "CH3": ch3}


def test_rigol_csv_sequence_rows_start_increment(tmp_path):
    time_s, volts = vendor_record()
    start, increment = float(time_s[0]), 2e-6
    path = tmp_path / "NewFile1.csv"
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\r\n")
        writer.writerow(["X", "CH1", "CH3", "Start", "Increment", ""])
        writer.writerow(["Sequence", "Volt", "Volt", f"{start:e}", f"{increment:e}", ""])
        for k in range(time_s.size):
            writer.writerow([k, f"{volts['CH1'][k]:e}", f"{volts['CH3'][k]:e}", ""])
    assert detect_format(path) == "rigol-csv"
    waves = read_waveforms(path, "auto")
    assert waves.format == "rigol-csv" and list(waves.channels) == ["CH1", "CH3"]
    np.testing.assert_allclose(waves.time_s, start + increment * np.arange(time_s.size), rtol=0, atol=1e-15)
    np.testing.assert_allclose(waves.time_s, time_s, rtol=0, atol=1e-12)
    for name in ("CH1", "CH3"):
        np.testing.assert_allclose(waves.channels[name], volts[name], rtol=1e-6, atol=1e-12)
    assert waves.lsb_v["CH1"] is None and waves.range_v["CH1"] is None
    # the same record refused with the reason when a row is short or the units row lacks Start
    text = path.read_text().splitlines()
    bad = tmp_path / "short.csv"
    bad.write_text("\n".join(text[:7] + [text[7].split(",")[0] + "," + text[7].split(",")[1]] + text[8:]))
    with pytest.raises(ScopeFileError, match=r"row 8 has 2 cells"):
        read_waveforms(bad)
    units_only = tmp_path / "nostart.csv"
    units_only.write_text("X,CH1,Start,Increment,\nSequence,Volt,\n0,1.0e-02,\n1,1.2e-02,\n")
    with pytest.raises(ScopeFileError, match="Start and Increment"):
        read_waveforms(units_only)


def test_keysight_infiniivision_and_infiniium_csv(tmp_path):
    time_s, volts = vendor_record()
    path = tmp_path / "scope_0.csv"
    lines = ["x-axis,1,3", "second,Volt,Volt"]
    lines += [f"{t:.6E},{a:.5E},{b:.5E}" for t, a, b in zip(time_s, volts["CH1"], volts["CH3"])]
    path.write_text("\n".join(lines) + "\n")
    assert detect_format(path) == "keysight-csv"
    waves = read_waveforms(path)
    assert list(waves.channels) == ["CH1", "CH3"]
    np.testing.assert_allclose(waves.time_s, time_s, rtol=1e-6, atol=0)
    np.testing.assert_allclose(waves.channels["CH3"], volts["CH3"], rtol=1e-5, atol=1e-12)

    infiniium = tmp_path / "wave_CH2.csv"
    header = ["Revision,0", "Type,raw", "Start,0", f"Points,{time_s.size}", "Count,1",
              "XDispRange,8.0E-04", f"XDispOrg,{time_s[0]:.9E}", "XInc,2.0E-06", f"XOrg,{time_s[0]:.9E}",
              "XUnits,Second", "YDispRange,8.0E-01", "YDispOrg,-4.0E-01", "YInc,1.6E-03", "YOrg,0.0",
              "YUnits,Volt", "Frame,DSO9104A:MY12345678", "Data"]
    infiniium.write_text("\n".join(header + [f"{v:.6E}" for v in volts["CH1"] * 1.0]) + "\n")
    assert detect_format(infiniium) == "keysight-csv"
    waves = read_waveforms(infiniium)
    assert list(waves.channels) == ["CH2"]
    np.testing.assert_allclose(waves.time_s, time_s, rtol=0, atol=1e-12)
    np.testing.assert_allclose(waves.channels["CH2"], volts["CH1"], rtol=1e-6, atol=1e-12)
    infiniium.write_text("\n".join(header[:3] + ["Points,5"] + header[4:] + ["1.0", "2.0"]) + "\n")
    with pytest.raises(ScopeFileError, match="Points says 5 but the file has 2"):
        read_waveforms(infiniium)


def test_lecroy_spreadsheet_csv(tmp_path):
    time_s, volts = vendor_record()
    path = tmp_path / "C2--shot--00003.txt"
    lines = ["LECROYWR640Zi,12345,Waveform", f"Segments,1,SegmentSize,{time_s.size}",
             "Segment,TrigTime,TimeSinceSegment1", "#1,26-Nov-2026 04:00:00,0", "Time,Ampl"]
    lines += [f"{t:.9e},{v:.6e}" for t, v in zip(time_s, volts["CH1"])]
    path.write_text("\r\n".join(lines) + "\r\n")
    assert detect_format(path) == "lecroy-csv"
    waves = read_waveforms(path)
    assert list(waves.channels) == ["C2"] and waves.info["instrument"].startswith("LECROYWR640Zi")
    np.testing.assert_allclose(waves.time_s, time_s, rtol=0, atol=1e-15)
    np.testing.assert_allclose(waves.channels["C2"], volts["CH1"], rtol=1e-6, atol=1e-12)
    lines[1] = "Segments,4,SegmentSize,100"
    path.write_text("\n".join(lines))
    with pytest.raises(ScopeFileError, match="4 segments"):
        read_waveforms(path)


@pytest.mark.parametrize("time_unit, factor, volt_unit, scale",
                         [("(ms)", 1e-3, "(mV)", 1e-3), ("(µs)", 1e-6, "(V)", 1.0)])
def test_picoscope_csv_units_row(tmp_path, time_unit, factor, volt_unit, scale):
    time_s, volts = vendor_record()
    path = tmp_path / "20261126-0001.csv"
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\r\n")
        writer.writerow(["Time", "Channel A", "Channel B"])
        writer.writerow([time_unit, volt_unit, "(V)"])
        writer.writerow([])
        for t, a, b in zip(time_s, volts["CH1"], volts["CH3"]):
            writer.writerow([f"{t / factor:.8f}", f"{a / scale:.8f}", f"{b:.8f}"])
    assert detect_format(path) == "pico-csv"
    waves = read_waveforms(path)
    assert list(waves.channels) == ["Channel A", "Channel B"]
    np.testing.assert_allclose(waves.time_s, time_s, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(waves.channels["Channel A"], volts["CH1"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(waves.channels["Channel B"], volts["CH3"], rtol=1e-6, atol=1e-9)
    text = path.read_text(encoding="utf-8").splitlines()
    text[10] = text[10].rsplit(",", 1)[0] + ",∞"
    path.write_text("\n".join(text), encoding="utf-8")
    with pytest.raises(ScopeFileError, match=r"row 11, column 3: '∞'.*beyond the range"):
        read_waveforms(path)
