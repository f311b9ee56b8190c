"""Bad inputs are refused before any work: exit code 2, one message naming the file and the key,
line or option and what was expected, no traceback, nothing written to --out.

Every test here runs with exubio.run.pipeline.reconstruct replaced by a failure, so a refusal that
comes only after (or instead of) a reconstruction fails the test.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

import exubio.run.pipeline
from exubio.cli import main
from exubio.errors import InputError
from exubio.io.c3d import read_c3d, write_c3d
from exubio.io.trc import write_trc
from exubio.model.load import DEFAULT_MODEL, load_model
from exubio.run.inputs import DEFAULT_PROTOCOL
from exubio.synth.simulate import Motion, simulate_trial
from exubio.types import Trajectories

HUGE = 10**400  # a YAML integer no float holds


@pytest.fixture(autouse=True)
def no_reconstruction(monkeypatch):
    def refuse(*args, **kwargs):
        pytest.fail("a reconstruction started: the bad input was not refused before the work")

    monkeypatch.setattr(exubio.run.pipeline, "reconstruct", refuse)


@pytest.fixture(scope="module")
def trajectories():
    return simulate_trial(load_model(), Motion.ABDUCTION, duration_s=1.0, rate_hz=50.0, seed=2).trajectories


@pytest.fixture()
def c3d(tmp_path, trajectories):
    return write_c3d(tmp_path / "trial.c3d", trajectories)


def refused(capsys, argv: list[str], out: Path, *needles: str) -> str:
    """main(argv) exits 2 with one message holding every needle, no traceback, and --out holds no
    file; an --out the run would have created is not left behind, empty."""
    existed = out.exists()
    code = main(["-q", *argv])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and err.count("exubio: error:") == 1, err
    for needle in needles:
        assert needle in err, (needle, err)
    assert not out.exists() or not [p for p in out.rglob("*") if p.is_file()], list(out.rglob("*"))
    assert existed or not out.exists(), f"{out} was created and left empty"
    return err


def reconstruct(trial: Path, out: Path, *extra: str) -> list[str]:
    return ["reconstruct", str(trial), "--method", "ls", "--no-report", "--out", str(out), *extra]


# ------------------------------------------------------------------------------------ model YAML
def _segment(data: dict, name: str) -> dict:
    return next(s for s in data["segments"] if s["name"] == name)


def _set_range(data, value):
    _segment(data, "clavicle")["joint"]["coordinates"][0]["range_deg"] = value


MODEL_EDITS = {
    # key named in the message: edit of the generic model's data
    "mass_fraction": lambda d: _segment(d, "clavicle")["inertia"].update(mass_fraction="abc"),
    "radii_mm": lambda d: d["ellipsoid"].update(radii_mm=["a", "b", "c"]),
    "body_mass_kg": lambda d: d.update(body_mass_kg="heavy"),
    "com_fraction": lambda d: _segment(d, "humerus")["inertia"].update(com_fraction=math.nan),
    "range_deg": lambda d: _set_range(d, [-50, math.inf]),
    "points_mm.AC": lambda d: _segment(d, "clavicle")["points_mm"].update(AC=[HUGE, 0, 0]),
    "principal_kgm2_per_kg": lambda d: _segment(d, "clavicle")["inertia"].update(
        principal_kgm2_per_kg=[-1e-3, 1e-3, 1e-4]),
    "com_between": lambda d: _segment(d, "scapula")["inertia"].update(com_between=["AC"]),
    "long_axis": lambda d: _segment(d, "humerus")["inertia"].update(long_axis=5),
    "contact_points": lambda d: d["ellipsoid"].update(contact_points=5),
    "calibration": lambda d: d.update(calibration="yes"),
    "radius_of_gyration_fraction": lambda d: _segment(d, "ulna")["inertia"].update(radius_of_gyration_fraction=HUGE),
}


@pytest.mark.parametrize("key", list(MODEL_EDITS))
def test_model_number_refused_naming_file_and_key(tmp_path, c3d, capsys, key):
    data = yaml.safe_load(Path(DEFAULT_MODEL).read_text(encoding="utf-8"))
    MODEL_EDITS[key](data)
    bad = tmp_path / "bad_model.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--model", str(bad)), out, "bad_model.yaml", key)


# --------------------------------------------------------------------------------- protocol YAML
PROTOCOL_EDITS = {
    "defaults.stiffness_n_per_m": lambda d: d["defaults"].update(stiffness_n_per_m=HUGE),
    "defaults.damping_ns_per_m": lambda d: d["defaults"].update(damping_ns_per_m=math.nan),
    "filter.cutoff_hz": lambda d: d["filter"].update(cutoff_hz=HUGE),
    "markers.ARM.local_position_mm": lambda d: d["markers"]["ARM"].update(local_position_mm=[0, HUGE, 0]),
    "markers.ARM.stiffness_n_per_m": lambda d: d["markers"]["ARM"].update(stiffness_n_per_m=math.inf),
}


@pytest.mark.parametrize("key", list(PROTOCOL_EDITS))
def test_protocol_number_refused_naming_file_and_key(tmp_path, c3d, capsys, key):
    data = yaml.safe_load(Path(DEFAULT_PROTOCOL).read_text(encoding="utf-8"))
    if key.endswith("local_position_mm"):
        data["markers"]["ARM"].pop("point")
    PROTOCOL_EDITS[key](data)
    bad = tmp_path / "bad_protocol.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--protocol", str(bad)), out, "bad_protocol.yaml", key)


# ------------------------------------------------------------------------------------------- TRC
def _trc_with(tmp_path: Path, trajectories: Trajectories, edit) -> Path:
    """The trial as a TRC file (rate 50 Hz, data from line 7) with ``edit(lines)`` applied."""
    path = write_trc(tmp_path / "trial.trc", trajectories)
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[5] == "" and lines[6].startswith("1\t0\t")
    edit(lines)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _set_time(lines: list[str], index: int, value: str) -> None:
    cells = lines[index].split("\t")
    cells[1] = value
    lines[index] = "\t".join(cells)


def test_trc_last_time_inf_refused_naming_the_line(tmp_path, trajectories, capsys):
    trc = _trc_with(tmp_path, trajectories, lambda lines: _set_time(lines, len(lines) - 1, "inf"))
    out = tmp_path / "out"
    n_lines = 6 + trajectories.n_frames
    refused(capsys, reconstruct(trc, out), out, "trial.trc", f"line {n_lines}", "Time", "'inf'")


def test_trc_time_going_back_refused_naming_both_lines(tmp_path, trajectories, capsys):
    trc = _trc_with(tmp_path, trajectories, lambda lines: _set_time(lines, 20, "0.1"))
    out = tmp_path / "out"
    refused(capsys, reconstruct(trc, out), out, "trial.trc", "line 21", "line 20", "increase")


def test_trc_data_rate_contradicting_the_time_column_refused(tmp_path, trajectories, capsys):
    def halve_times(lines):  # header 50 Hz, time steps of 0.01 s
        for i in range(6, len(lines)):
            _set_time(lines, i, f"{(i - 6) * 0.01:.10g}")

    trc = _trc_with(tmp_path, trajectories, halve_times)
    out = tmp_path / "out"
    refused(capsys, reconstruct(trc, out), out, "trial.trc", "line 9", "DataRate 50 Hz", "Time is 0.02 s")


# ------------------------------------------------------------------------------------------- C3D
def test_c3d_over_65535_frames_round_trips_whole(tmp_path):
    """The header counts frames in 16 bits (ezc3d reads 65535 of them): write_c3d stores the count
    in POINT:LONG_FRAMES and TRIAL:ACTUAL_*_FIELD, and read_c3d reads every frame."""
    n = 70_000
    rng = np.random.default_rng(3)
    pos = rng.uniform(-1.0, 1.0, size=(n, 2, 3))
    pos[10, 0] = np.nan
    pos[n - 3, 1] = np.nan  # a gap beyond frame 65535
    traj = Trajectories(("A", "B"), pos, 100.0, np.arange(n) / 100.0)
    got = read_c3d(write_c3d(tmp_path / "long.c3d", traj))
    assert got.n_frames == n and got.labels == ("A", "B")
    assert np.array_equal(np.isnan(got.positions_m), np.isnan(pos))
    assert np.nanmax(np.abs(got.positions_m - pos)) < 1e-6
    assert got.time_s[-1] == pytest.approx((n - 1) / 100.0)


def _long_c3d_without_count(path: Path, n: int) -> Path:
    """A C3D of n > 65535 frames as ezc3d alone writes it: header and POINT:FRAMES say 65535."""
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = np.array([100.0])
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("A", "B")
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    points = np.ones((4, 2, n))
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"]["residuals"] = np.zeros((1, 2, n))
    c3d.write(str(path))
    return path


def test_c3d_over_65535_frames_without_a_count_refused(tmp_path):
    path = _long_c3d_without_count(tmp_path / "nocount.c3d", 70_000)
    with pytest.raises(InputError, match=r"nocount\.c3d: .*65535.*POINT:LONG_FRAMES"):
        read_c3d(path)


def test_c3d_over_65535_frames_truncated_refused(tmp_path):
    traj = Trajectories(("A", "B"), np.zeros((70_000, 2, 3)), 100.0, np.arange(70_000) / 100.0)
    path = write_c3d(tmp_path / "cut.c3d", traj)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 40_000])
    with pytest.raises(InputError, match=r"cut\.c3d: .*truncated.*70000 frames"):
        read_c3d(path)


# ------------------------------------------------------- C3D headers that contradict themselves
def _patched(path: Path, *edits: tuple[int, bytes], name: str = "hostile.c3d") -> Path:
    """A copy of the C3D ``path`` with ``(offset, bytes)`` edits applied."""
    data = bytearray(path.read_bytes())
    for offset, new in edits:
        data[offset:offset + len(new)] = new
    out = path.with_name(name)
    out.write_bytes(bytes(data))
    return out


def _float_offsets(path: Path, value: float) -> list[int]:
    """Byte offsets of ``value`` as a little-endian float32 (the writer's Intel format)."""
    data, needle = path.read_bytes(), struct.pack("<f", value)
    return [i for i in range(len(data) - 3) if data[i:i + 4] == needle]


def _point_rate_offset(path: Path) -> int:
    """The offset of POINT:RATE's value (50 Hz) in the parameter section: the float 50 there that,
    patched, changes what ezc3d reads as POINT:RATE."""
    import ezc3d

    for offset in _float_offsets(path, 50.0):
        if offset < 512:
            continue
        probe = _patched(path, (offset, struct.pack("<f", 77.0)), name="probe.c3d")
        if float(ezc3d.c3d(str(probe))["parameters"]["POINT"]["RATE"]["value"][0]) == 77.0:
            probe.unlink()
            return offset
    raise AssertionError("POINT:RATE not found")


@pytest.mark.parametrize("rate, expected", [(math.nan, "nan (not a finite number)"),
                                            (math.inf, "inf (not a finite number)"),
                                            (1e9, "1e+09 Hz (above 100000 Hz")])
def test_c3d_rate_nan_infinite_or_1e9_refused_naming_point_rate(tmp_path, c3d, capsys, rate, expected):
    """ezc3d crashes on a NaN POINT:RATE (vector::_M_default_append), an infinite one overflowed in
    the preprocessing and 1e9 Hz made the filter's end padding ask for 15 GB: refused before reading."""
    bad = _patched(c3d, (20, struct.pack("<f", rate)), (_point_rate_offset(c3d), struct.pack("<f", rate)))
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d", "POINT:RATE is " + expected)


def test_c3d_parameter_block_past_the_end_refused(tmp_path, c3d, capsys):
    bad = _patched(c3d, (0, bytes([200])))
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d", "parameter block at 512-byte block 200",
            f"the file has {c3d.stat().st_size} bytes")


def test_c3d_data_start_past_the_end_refused(tmp_path, c3d, capsys):
    bad = _patched(c3d, (16, struct.pack("<H", 500)))
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d", "word 9 puts the data at 512-byte block 500")


def test_c3d_last_frame_before_the_first_read_as_the_data_hold_with_a_warning(c3d, trajectories, caplog):
    bad = _patched(c3d, (6, struct.pack("<2H", 40, 10)))
    with caplog.at_level("WARNING", logger="exubio.io.c3d"):
        got = read_c3d(bad)
    assert got.n_frames == trajectories.n_frames
    assert np.array_equal(got.positions_m, read_c3d(c3d).positions_m, equal_nan=True)
    (finding,) = got.input_findings
    assert "last frame (word 5) is 10, before its first frame (word 4) 40" in finding and "hostile.c3d" in finding
    assert finding in caplog.text
    assert read_c3d(c3d).input_findings == ()


def test_c3d_header_of_65535_frames_over_100_frames_read_with_a_warning(tmp_path, caplog):
    traj = Trajectories(("A", "B"), np.random.default_rng(1).uniform(-1, 1, (100, 2, 3)), 100.0,
                        np.arange(100) / 100.0)
    good = write_c3d(tmp_path / "short.c3d", traj)
    bad = _patched(good, (8, struct.pack("<H", 65535)))
    with caplog.at_level("WARNING", logger="exubio.io.c3d"):
        got = read_c3d(bad)
    assert got.n_frames == 100
    assert np.nanmax(np.abs(got.positions_m - traj.positions_m)) < 1e-6
    (finding,) = got.input_findings
    assert "last frame (word 5) is 65535" in finding and "no POINT:LONG_FRAMES" in finding and "holds 100" in finding
    assert finding in caplog.text


def test_c3d_parameter_dimensions_past_the_parameter_section_refused(tmp_path, c3d, capsys):
    """POINT:LABELS declared 255 x 255 characters (65 kB) in a 1 kB section: ezc3d read past its
    buffer and the process died of a segmentation fault."""
    from exubio.io import c3d as c3d_module

    byte_order, _, header = c3d_module._raw_header(c3d)
    section, params = c3d_module._raw_parameters(c3d, byte_order, header[0], c3d.stat().st_size)
    (start,) = [st for group, name, _, st in params if (group, name) == ("POINT", "LABELS")]
    dims_at = (header[0] - 1) * 512 + start - 2  # a 2-D char array: (label length, number of labels)
    bad = _patched(c3d, (dims_at, bytes([255, 255])))
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d", "POINT:LABELS declares dimensions [255, 255]",
            "parameter section")


def test_c3d_parameter_turned_into_a_group_by_one_byte_refused(tmp_path, c3d, capsys):
    """One byte (the group id of ANALOG:LABELS made negative, which marks a group record) crashed
    ezc3d with a segmentation fault (found by mutating random bytes of the parameter section)."""
    from exubio.io import c3d as c3d_module

    byte_order, _, header = c3d_module._raw_header(c3d)
    _, params = c3d_module._raw_parameters(c3d, byte_order, header[0], c3d.stat().st_size)
    (start,) = [st for group, name, _, st in params if (group, name) == ("ANALOG", "LABELS")]
    ident_at = (header[0] - 1) * 512 + start - 13  # the record: chars, id, "LABELS", offset (2), type, dims (2)
    bad = _patched(c3d, (ident_at, bytes([155])))
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d", "parameter section")


def test_c3d_char_parameter_without_dimensions_refused(tmp_path, c3d, capsys):
    """One byte (a scalar's type made char, -1) crashed ezc3d with a segmentation fault: it reads a
    char parameter's first dimension, which a scalar has not (found by mutating the section's bytes)."""
    from exubio.io import c3d_raw

    byte_order, _, header = c3d_raw.raw_header(c3d)
    _, params = c3d_raw.parameter_records(c3d, byte_order, header[0], c3d.stat().st_size)
    scalar = next(p for p in params if p.dims == () and p.kind != -1)
    bad = _patched(c3d, ((header[0] - 1) * 512 + scalar.start - 2, bytes([255])))  # type, n_dims = 0, data
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d",
            f"parameter {scalar.group}:{scalar.name} is of type char with no dimension")


def _moved_to_point(c3d: Path, name: str, *, out: str) -> Path:
    """A copy of ``c3d`` whose ANALOG:``name`` record says it belongs to the POINT group (its group
    id byte), so that POINT holds ``name`` twice and ezc3d keeps this one, the last."""
    from exubio.io import c3d_raw

    byte_order, _, header = c3d_raw.raw_header(c3d)
    section, params = c3d_raw.parameter_records(c3d, byte_order, header[0], c3d.stat().st_size)
    (moved,) = [p for p in params if (p.group, p.name) == ("ANALOG", name)]
    record = moved.start - len(moved.dims) - 4 - len(name) - 2  # chars, id, name, offset (2), type, n dims, dims
    point_id = next(section[p.start - len(p.dims) - 4 - len(p.name) - 1] for p in params if p.group == "POINT")
    return _patched(c3d, ((header[0] - 1) * 512 + record + 1, bytes([point_id])), name=out)


def test_c3d_point_scale_without_a_value_refused(tmp_path, c3d, capsys):
    """ANALOG:SCALE (no value) moved into the POINT group by one byte: ezc3d kept it as POINT:SCALE and
    read its first value, which it has not: a segmentation fault (found by mutating the section)."""
    bad = _moved_to_point(c3d, "SCALE", out="hostile.c3d")
    out = tmp_path / "out"
    refused(capsys, reconstruct(bad, out), out, "hostile.c3d", "parameter POINT:SCALE holds no value")


def test_c3d_parameter_defined_twice_read_as_ezc3d_reads_it_with_a_finding(c3d, trajectories):
    bad = _moved_to_point(c3d, "UNITS", out="twice.c3d")  # POINT:UNITS, then an empty one
    got = read_c3d(bad)
    np.testing.assert_allclose(got.positions_m, read_c3d(c3d).positions_m, atol=1e-9)
    assert any("POINT:UNITS defined twice or more; read the last definition" in f for f in got.input_findings)
    assert any("POINT:UNITS is absent; read as millimetres" in f for f in got.input_findings)


@pytest.mark.parametrize("value", [-5.0, 0.0, 2.5])
def test_c3d_point_long_frames_not_a_count_refused(tmp_path, value):
    n = 70_000
    traj = Trajectories(("A",), np.zeros((n, 1, 3)), 100.0, np.arange(n) / 100.0)
    good = write_c3d(tmp_path / "long.c3d", traj)
    (offset,) = [o for o in _float_offsets(good, float(n)) if o >= 512]  # POINT:LONG_FRAMES
    bad = _patched(good, (offset, struct.pack("<f", value)))
    with pytest.raises(InputError, match=rf"hostile\.c3d: .*POINT:LONG_FRAMES is {value:g}; expected the number of"):
        read_c3d(bad)


# ---------------------------------------------------------------------------------- CLI options
def test_static_frames_past_the_end_refused_naming_window_and_frame_count(tmp_path, c3d, capsys):
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--static-frames", "40:80"), out, "trial.c3d", "40:80", "50 frames")
    refused(capsys, reconstruct(c3d, out, "--static", str(c3d), "--static-frames", "10:60"), out,
            "trial.c3d", "10:60", "50 frames")


@pytest.mark.parametrize("jobs", ["0", "-1"])
def test_jobs_below_one_refused_before_any_calibration(tmp_path, c3d, capsys, monkeypatch, jobs):
    monkeypatch.setattr(exubio.run.pipeline, "read_trial", lambda *a, **k: pytest.fail("a trial was read"))
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--jobs", jobs), out, f"--jobs {jobs}", ">= 1")
    refused(capsys, reconstruct(c3d, out, "--jobs", jobs, "--static", str(c3d)), out, f"--jobs {jobs}")


def _unwritable_folder() -> Path:
    """An existing folder no file can be created in, even by root (procfs), else skip."""
    folder = Path("/proc")
    try:
        (folder / "exubio-probe").write_text("")
    except OSError:
        return folder
    pytest.skip("no unwritable folder on this system")


@pytest.mark.parametrize("where", ["unwritable", "file", "under-a-file", "not-creatable"])
def test_output_folder_checked_before_reading_anything(tmp_path, c3d, capsys, monkeypatch, where):
    monkeypatch.setattr(exubio.run.pipeline, "read_trial", lambda *a, **k: pytest.fail("a trial was read"))
    (tmp_path / "a_file").write_text("not a folder")
    out = {"unwritable": _unwritable_folder, "file": lambda: tmp_path / "a_file",
           "under-a-file": lambda: tmp_path / "a_file" / "results",
           "not-creatable": lambda: _unwritable_folder() / "results"}[where]()
    nothing_in = tmp_path / "nothing"  # the folders refused here cannot hold anything written
    refused(capsys, reconstruct(c3d, out), nothing_in, str(out))
    refused(capsys, reconstruct(c3d, out, "--static", str(c3d)), nothing_in, str(out))
    model_out = out / "subject.yaml"
    refused(capsys, ["calibrate", str(c3d), "--out", str(model_out)], nothing_in, str(out))
    assert (tmp_path / "a_file").read_text() == "not a folder"


# ------------------------------------------------------------------- deep YAML, singular holds
def _deep(kind: str) -> str:
    """A YAML mapping nested 5000 levels deep, in flow ([[[...]]]) or block (indented keys) style."""
    if kind == "flow":
        return "schema_version: 1\nx: " + "[" * 5000 + "]" * 5000 + "\n"
    return "schema_version: 1\n" + "".join("  " * i + f"k{i}:\n" for i in range(5000)) + "  " * 5000 + "v: 1\n"


@pytest.mark.parametrize("kind", ["flow", "block"])
@pytest.mark.parametrize("option", ["--model", "--protocol"])
def test_yaml_nested_5000_levels_refused_naming_file_and_line(tmp_path, c3d, capsys, option, kind):
    """It raised RecursionError (PyYAML's composer and the duplicate-key walk recurse per level)."""
    deep = tmp_path / "deep.yaml"
    deep.write_text(_deep(kind), encoding="utf-8")
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, option, str(deep)), out, "deep.yaml", "nested more than 64 levels")


def test_protocol_holding_every_coordinate_refused_naming_hold(tmp_path, c3d, capsys):
    """Every coordinate held left a singular system (numpy LinAlgError: Singular matrix) in LS."""
    data = yaml.safe_load(Path(DEFAULT_PROTOCOL).read_text(encoding="utf-8"))
    data["hold"] = list(load_model().coordinate_names)
    bad = tmp_path / "hold_all.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--protocol", str(bad)), out, "hold_all.yaml", "hold", "every coordinate")


def test_protocol_holding_the_scapula_chain_but_one_refused(tmp_path, c3d, capsys):
    """Two ellipsoid contact constraints on one free coordinate cannot be met (also a singular system)."""
    data = yaml.safe_load(Path(DEFAULT_PROTOCOL).read_text(encoding="utf-8"))
    data["hold"] = [c for c in load_model().coordinate_names if c.startswith(("sc_", "ac_"))][:5]
    bad = tmp_path / "hold_girdle.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--protocol", str(bad)), out, "hold_girdle.yaml", "hold", "scapula",
            "need at least 2")


# --------------------------------------------------------------------------- results, duplicates
def _a_result(tmp_path: Path) -> Path:
    """A real .npz result (LS, written by write_outputs's writer) without running a method."""
    from exubio.io.results import write_npz
    from exubio.types import Reconstruction

    n, names = 5, load_model().coordinate_names
    recon = Reconstruction(method="ls", time_s=np.arange(n) / 50.0, coordinate_names=names,
                           q_rad=np.zeros((n, len(names))), qd_rad_s=np.zeros((n, len(names))),
                           qdd_rad_s2=np.zeros((n, len(names))), marker_names=("A",),
                           model_points_m=np.zeros((n, 1, 3)), measured_m=np.zeros((n, 1, 3)),
                           residuals_m=np.zeros((n, 1)), constraint=np.zeros((n, 2)),
                           constraint_velocity=np.zeros((n, 2)), status=np.zeros(n, dtype=int))
    return write_npz(tmp_path / "trial.ls.npz", recon, metadata={"trial": "trial.c3d"})


@pytest.mark.parametrize("keep", [0.5, 0.98])
def test_view_of_a_truncated_npz_refused_naming_it(tmp_path, capsys, keep):
    """It ended in zipfile.BadZipFile."""
    path = _a_result(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    out = tmp_path / "view"
    refused(capsys, ["view", str(path), "--out", str(out / "v.html")], out, "trial.ls.npz",
            "not a readable .npz file", "BadZipFile")


def test_view_of_an_npz_with_a_damaged_entry_refused_naming_it(tmp_path, capsys):
    path = _a_result(tmp_path)
    data = bytearray(path.read_bytes())
    at = data.index(b"q_rad.npy") + 200  # inside the q_rad entry's data
    data[at:at + 40] = b"\xff" * 40
    path.write_bytes(bytes(data))
    out = tmp_path / "view"
    refused(capsys, ["view", str(path), "--out", str(out / "v.html")], out, "trial.ls.npz", "damaged")


@pytest.mark.parametrize("spelling", ["same", "dotted"])
def test_the_same_trial_twice_refused_before_anything_is_written(tmp_path, c3d, capsys, spelling):
    """It wrote the first copy's four result files, then refused the second."""
    again = str(c3d) if spelling == "same" else str(c3d.parent / "." / c3d.name)
    out = tmp_path / "out"
    argv = ["reconstruct", str(c3d), again, "--method", "ls", "--no-report", "--out", str(out)]
    refused(capsys, argv, out, "trial.c3d", "the same trial is given twice")


# --------------------------------------------------------------- corpus defects (issue 35 item 5)
def _model_with(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load(Path(DEFAULT_MODEL).read_text(encoding="utf-8"))
    edit(data)
    bad = tmp_path / "bad_model.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return bad


def _rename_coordinate(segment: str, k: int, name: str):
    return lambda d: _segment(d, segment)["joint"]["coordinates"][k].update(name=name)


@pytest.mark.parametrize("segment, k, where", [("scapula", 0, "segments[2].joint.coordinates[0].name"),
                                               ("clavicle", 1, "segments[1].joint.coordinates[1].name")])
def test_model_with_a_coordinate_named_twice_refused_naming_both_places(tmp_path, c3d, capsys, segment, k, where):
    """It was a traceback (exit 1) once the run built its tables."""
    bad = _model_with(tmp_path, _rename_coordinate(segment, k, "sc_protraction"))
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--model", str(bad)), out, "bad_model.yaml", where,
            "coordinate 'sc_protraction' is named twice", "segments[1].joint.coordinates[0].name")


def test_model_side_middle_refused_naming_the_key_and_the_allowed_values(tmp_path, c3d, capsys):
    bad = _model_with(tmp_path, lambda d: d.update(side="middle"))
    out = tmp_path / "out"
    refused(capsys, reconstruct(c3d, out, "--model", str(bad)), out, "bad_model.yaml", "side: expected 'right' or "
            "'left'", "'middle'")
    assert load_model(_model_with(tmp_path, lambda d: d.update(side="left"))).metadata["side"] == "left"


def test_numbers_written_with_an_exponent_are_numbers_in_a_model_and_a_protocol(tmp_path):
    """PyYAML (YAML 1.1) reads `2e3` as text, which was refused as "not a number"."""
    from exubio.protocol.load import load_protocol

    text = Path(DEFAULT_MODEL).read_text(encoding="utf-8")
    written = yaml.safe_load(text)
    written["body_mass_kg"] = "MASS"
    model_file = tmp_path / "model.yaml"
    model_file.write_text(yaml.safe_dump(written, sort_keys=False).replace("MASS", "7.5e1"), encoding="utf-8")
    model = load_model(model_file)
    assert model.body_mass_kg == 75.0
    assert load_model(DEFAULT_MODEL).body_mass_kg == 75.0  # the same model as the generic one
    protocol_text = Path(DEFAULT_PROTOCOL).read_text(encoding="utf-8")
    assert "stiffness_n_per_m: 1500," in protocol_text
    protocol_file = tmp_path / "protocol.yaml"
    protocol_file.write_text(protocol_text.replace("stiffness_n_per_m: 1500,", "stiffness_n_per_m: 2e3,"),
                             encoding="utf-8")
    kwargs = dict(segments=[s.name for s in model.segments], model_points={s.name: s.points for s in model.segments})
    assert load_protocol(protocol_file, **kwargs).default_stiffness_n_per_m == 2000.0
    assert load_protocol(DEFAULT_PROTOCOL, **kwargs).default_stiffness_n_per_m == 1500.0
    quoted = tmp_path / "quoted.yaml"  # text stays text: a quoted "2e3" is still refused
    quoted.write_text(protocol_text.replace("stiffness_n_per_m: 1500,", "stiffness_n_per_m: '2e3',"), encoding="utf-8")
    with pytest.raises(Exception, match=r"quoted\.yaml: .*stiffness_n_per_m"):
        load_protocol(quoted, **kwargs)


def test_c3d_point_rate_0_read_at_the_header_rate_with_a_finding(c3d, trajectories):
    """POINT:RATE 0 was refused although the header (word 11-12) holds the 50 Hz the trial has."""
    bad = _patched(c3d, (_point_rate_offset(c3d), struct.pack("<f", 0.0)))
    got = read_c3d(bad)
    assert got.rate_hz == 50.0 and got.n_frames == trajectories.n_frames
    np.testing.assert_allclose(got.time_s, np.arange(got.n_frames) / 50.0)
    (finding,) = got.input_findings
    assert "POINT:RATE is 0 Hz (not > 0); read at the header's rate (word 11-12), 50 Hz" in finding
    both = _patched(c3d, (20, struct.pack("<f", 0.0)), (_point_rate_offset(c3d), struct.pack("<f", 0.0)),
                    name="both.c3d")
    with pytest.raises(InputError, match=r"both\.c3d: POINT:RATE is 0 Hz \(not > 0\)"):
        read_c3d(both)
