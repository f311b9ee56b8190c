"""exubio.io.c3d: real Vicon files (fingerprints), synthetic files (labels, units, gaps), round
trips and refusal of broken files. Special files are crafted through the private builder of the
module so that ezc3d stays imported by exubio/io/c3d.py only."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError
from exubio.io.c3d import _build_c3d, read_c3d, strip_prefix, write_c3d
from exubio.io.trial import read_trial
from exubio.types import Trajectories

SHARED_C3D = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d"
STATIC_LABELS = (
    "C7 T10 MAN XYP CLAV_SC CLAV_AC SCAP_BACK SCAP_IA SCAP_AA SCAP_AC SCAP_FRONT SCAP_Cor "
    "ARM EPI_med EPI_lat DELT ULNA RADIUS SEML MET5 MET2"
).split()
# float32 storage: |error| <= 2**-24 * |x|, i.e. < 1e-7 m for the ~1 m positions used here
TOL_M = 1e-6


def shared(name: str) -> Path:
    path = SHARED_C3D / name
    if not path.is_file():
        pytest.skip(f"shared data file {path} not available")
    return path


def make_trajectories(labels, n_frames=50, rate=100.0, seed=0) -> Trajectories:
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-1.5, 1.5, size=(n_frames, len(labels), 3))
    return Trajectories(labels=tuple(labels), positions_m=pos, rate_hz=rate, time_s=np.arange(n_frames) / rate)


def write_custom(path: Path, traj: Trajectories, *, units="mm", edit=None) -> Path:
    """A C3D built like write_c3d does, with ``edit(c3d)`` applied before writing."""
    c3d = _build_c3d(traj, units)
    if edit is not None:
        edit(c3d)
    c3d.write(str(path))
    return path


# ------------------------------------------------------------------------- real files
def test_static_trial_fingerprint():
    traj = read_c3d(shared("bioptim_exo_martin_statique.c3d"))
    assert traj.positions_m.shape == (272, 21, 3)
    assert traj.labels == tuple(STATIC_LABELS)
    assert traj.ignored_labels == ()
    assert traj.rate_hz == 100.0 and traj.units_in_file == "mm"
    np.testing.assert_allclose(traj.time_s, np.arange(272) / 100.0)
    assert np.isnan(traj.positions_m).sum() == 0
    norms = np.linalg.norm(traj.positions_m, axis=2)
    assert 0.1 < np.median(norms) < 2.0 and norms.max() < 2.0  # metres, not millimetres
    np.testing.assert_allclose(traj.marker("MET2")[0], [-0.7617515, 0.7417632, 0.3931145], atol=1e-6)
    assert traj.positions_m.dtype == np.float64


def test_drinking_trial_drops_unlabelled_markers():
    traj = read_c3d(shared("bioptim_exo_F0_boire_05.c3d"))
    assert traj.positions_m.shape == (621, 22, 3)
    assert traj.ignored_labels == ("*22", "*23", "*24", "*25", "*26", "*27")
    assert "ELB" in traj.labels and not any(lab.startswith("*") for lab in traj.labels)
    assert np.isnan(traj.positions_m).sum() == 0  # the only gappy marker (*27) is unlabelled
    assert traj.time_s[0] == 0.0 and traj.time_s[-1] == pytest.approx(6.2)
    np.testing.assert_allclose(traj.marker("ELB")[0], [-0.4869397, 0.2419459, 0.0526335], atol=1e-6)


def test_read_trial_dispatches_c3d_case_insensitively(tmp_path):
    traj = make_trajectories(["A", "B"])
    path = write_c3d(tmp_path / "trial.C3D", traj)
    assert read_trial(path).labels == ("A", "B")


# ------------------------------------------------------------------------- labels, units, gaps
def test_prefixes_unlabelled_duplicates_and_empty_labels(tmp_path):
    raw = ("Martin:C7", " Bob:ARM ", "*3", "Other:C7", "T10", "Subj:")
    traj = make_trajectories(raw)
    got = read_c3d(write_custom(tmp_path / "labels.c3d", traj))
    assert got.labels == ("C7", "ARM", "T10")
    assert got.ignored_labels[0] == "*3" and got.ignored_labels[1:] == ("Other:C7", "Subj:")
    # the first C7 (Martin's) is the one kept
    np.testing.assert_allclose(got.marker("C7"), traj.positions_m[:, 0], atol=TOL_M)
    np.testing.assert_allclose(got.marker("T10"), traj.positions_m[:, 4], atol=TOL_M)


@pytest.mark.parametrize("raw, expected", [("Martin:ARM", "ARM"), ("a:b:ELB ", "ELB"), (" C7", "C7"), ("*12", "*12")])
def test_strip_prefix(raw, expected):
    assert strip_prefix(raw) == expected


@pytest.mark.parametrize("units, factor", [("mm", 1e3), ("cm", 1e2), ("m", 1.0)])
def test_units_are_converted_to_metres(tmp_path, units, factor):
    traj = make_trajectories(["A", "B", "C"])
    path = write_c3d(tmp_path / "u.c3d", traj, units=units)
    got = read_c3d(path)
    assert got.units_in_file == units
    np.testing.assert_allclose(got.positions_m, traj.positions_m, rtol=0, atol=TOL_M)


def test_unknown_unit_is_refused_naming_it(tmp_path):
    def set_inches(c3d):
        c3d["parameters"]["POINT"]["UNITS"]["value"] = ["in"]

    path = write_custom(tmp_path / "inches.c3d", make_trajectories(["A"]), edit=set_inches)
    with pytest.raises(InputError, match=r"inches\.c3d.*'in'.*\['cm', 'm', 'mm'\]"):
        read_c3d(path)


def test_absent_unit_assumes_millimetres_and_says_so(tmp_path):
    def drop_units(c3d):
        c3d["parameters"]["POINT"]["UNITS"]["value"] = []

    traj = make_trajectories(["A"])
    got = read_c3d(write_custom(tmp_path / "nounit.c3d", traj, units="mm", edit=drop_units))
    assert got.units_in_file == "mm (assumed)"
    np.testing.assert_allclose(got.positions_m, traj.positions_m, atol=TOL_M)


def test_negative_residual_is_missing_even_with_zero_coordinates(tmp_path):
    traj = make_trajectories(["A", "B"], n_frames=4)

    def edit(c3d):
        points = c3d["data"]["points"]
        points[:3, 0, 1] = 0.0  # A, frame 1: (0,0,0) with residual -1 -> missing
        points[:3, 1, 2] = 0.0  # B, frame 2: (0,0,0) with residual 0 -> a real sample at the origin
        res = c3d["data"]["meta_points"]["residuals"]
        res[0, 0, 1] = -1.0
        c3d["data"]["points"] = points
        c3d["data"]["meta_points"]["residuals"] = res

    got = read_c3d(write_custom(tmp_path / "gaps.c3d", traj, edit=edit))
    missing = np.isnan(got.positions_m).any(axis=2)
    assert missing.sum() == 1 and missing[1, 0]
    assert np.isnan(got.positions_m[1, 0]).all()
    np.testing.assert_array_equal(got.positions_m[2, 1], [0.0, 0.0, 0.0])


def test_round_trip_keeps_nan_samples_and_all_nan_marker(tmp_path):
    traj = make_trajectories(["A", "B", "GONE"], n_frames=30, rate=150.0)
    pos = traj.positions_m.copy()
    pos[5:9, 0] = np.nan
    pos[:, 2] = np.nan
    traj = Trajectories(traj.labels, pos, traj.rate_hz, traj.time_s)
    got = read_c3d(write_c3d(tmp_path / "rt.c3d", traj))
    assert got.labels == traj.labels and got.ignored_labels == ()
    assert got.rate_hz == 150.0
    np.testing.assert_allclose(got.time_s, np.arange(30) / 150.0)
    np.testing.assert_array_equal(np.isnan(got.positions_m), np.isnan(pos))
    np.testing.assert_allclose(got.positions_m, pos, rtol=0, atol=TOL_M, equal_nan=True)
    assert got.source == str(tmp_path / "rt.c3d")


def test_written_file_marks_missing_samples_with_residual_minus_one():
    traj = make_trajectories(["A"], n_frames=3)
    pos = traj.positions_m.copy()
    pos[1, 0, 2] = np.nan  # one NaN coordinate makes the whole sample missing
    c3d = _build_c3d(Trajectories(("A",), pos, 100.0, traj.time_s), "mm")
    np.testing.assert_array_equal(c3d["data"]["meta_points"]["residuals"][0, 0], [0.0, -1.0, 0.0])
    np.testing.assert_array_equal(c3d["data"]["points"][:3, 0, 1], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(c3d["data"]["points"][:3, 0, 0], pos[0, 0] * 1e3)


# ------------------------------------------------------------------------- broken input
def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(InputError, match="nope.c3d: file not found"):
        read_c3d(tmp_path / "nope.c3d")


def test_folder_is_refused(tmp_path):
    with pytest.raises(InputError, match="folder"):
        read_c3d(tmp_path)


@pytest.mark.parametrize(
    "content",
    [b"", b"hello, this is not a C3D file\n", bytes(range(256)) * 20, b"\x02\x50" + b"\x00" * 98],
    ids=["empty", "text", "binary", "header-only"],
)
def test_garbage_is_an_input_error(tmp_path, content):
    path = tmp_path / "bad.c3d"
    path.write_bytes(content)
    with pytest.raises(InputError, match=r"bad\.c3d: not a readable C3D file \("):
        read_c3d(path)


@pytest.mark.parametrize("keep_fraction", [0.05, 0.6, 0.97])
def test_truncated_file_is_an_input_error(tmp_path, keep_fraction):
    good = write_c3d(tmp_path / "good.c3d", make_trajectories(["A", "B", "C"], n_frames=400))
    data = good.read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(data[: int(len(data) * keep_fraction)])
    with pytest.raises(InputError, match=r"cut\.c3d: not a readable C3D file"):
        read_c3d(cut)


# ------------------------------------------------------------------------- writing
@pytest.mark.parametrize("name", ["out.c3d", "OUT.C3D", "no_suffix"])
def test_write_replaces_the_target_and_leaves_no_temporary_file(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"old content")
    write_c3d(path, make_trajectories(["A"]))
    assert [p.name for p in tmp_path.iterdir()] == [name]
    assert read_c3d(path).labels == ("A",)


def test_write_refusals_keep_the_existing_file(tmp_path):
    path = tmp_path / "out.c3d"
    path.write_bytes(b"old content")
    with pytest.raises(InputError, match=r"out\.c3d.*'inch'"):
        write_c3d(path, make_trajectories(["A"]), units="inch")
    empty = Trajectories(("A",), np.empty((0, 1, 3)), 100.0, np.empty(0))
    with pytest.raises(InputError, match="0 frames"):
        write_c3d(path, empty)
    assert path.read_bytes() == b"old content"
    with pytest.raises(InputError, match="does not exist"):
        write_c3d(tmp_path / "missing" / "x.c3d", make_trajectories(["A"]))


# ------------------------------------------------------------------------- vendors' oddities
def test_a_parameter_named_with_spaces_is_read_with_a_finding(tmp_path):
    """Qualisys QTM writes PROCESSING parameters named with spaces (BTS: SUBJECT:PELVIS WIDTH); ezc3d
    reads them, and exubio refused the whole file."""
    traj = make_trajectories(["A", "B"])
    path = write_custom(tmp_path / "qtm.c3d", traj, edit=lambda c: c.add_parameter(
        "PROCESSING", "Uncropped Measurement Length", np.array([12.5])))
    got = read_c3d(path)
    np.testing.assert_allclose(got.positions_m, traj.positions_m, atol=TOL_M)
    (finding,) = got.input_findings
    assert "qtm.c3d" in finding and "'PROCESSING:UNCROPPED MEASUREMENT LENGTH'" in finding and "naming rule" in finding


def test_parameters_past_the_declared_section_length_are_read_with_a_finding(tmp_path):
    """Peak Performance and PhoeniX files declare a parameter section shorter than their records
    (byte 3 of the section); ezc3d reads the records where they are."""
    traj = make_trajectories(["A", "B"])
    path = write_c3d(tmp_path / "peak.c3d", traj)
    data = bytearray(path.read_bytes())
    first = (data[0] - 1) * 512
    assert data[first + 2] >= 2
    data[first + 2] = 1
    path.write_bytes(bytes(data))
    got = read_c3d(path)
    np.testing.assert_allclose(got.positions_m, traj.positions_m, atol=TOL_M)
    (finding,) = got.input_findings
    assert "declares 1 block(s) (512 bytes) but its records run to byte" in finding


def test_a_file_marked_sgi_mips_that_is_not_big_endian_is_refused_not_crashed(tmp_path):
    """Byte 4 set to 86 on an Intel file: read big-endian, its header points past the file's end."""
    path = write_c3d(tmp_path / "sgi.c3d", make_trajectories(["A"]))
    data = bytearray(path.read_bytes())
    data[(data[0] - 1) * 512 + 3] = 86
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"sgi\.c3d: not a readable C3D file \(the header contradicts the file"):
        read_c3d(path)


def test_a_description_longer_than_127_characters_is_read_with_a_finding(tmp_path):
    """ezc3d writes a 160-character group description with a length byte its own reader takes as
    negative (KINARM's Dexterit-E writes such files): ezc3d cannot read the file back (it reports a
    format that is not standard, after some 35 s: not run here), exubio can."""
    traj = make_trajectories(["A", "B"])

    def long_description(c3d):
        c3d["parameters"]["POINT"]["__METADATA__"]["DESCRIPTION"] = "x" * 160

    path = write_custom(tmp_path / "kinarm.c3d", traj, edit=long_description)
    data = path.read_bytes()
    assert data[data.index(b"POINT") + len("POINT") + 2] == 160  # the group's description length byte
    got = read_c3d(path)
    np.testing.assert_allclose(got.positions_m, traj.positions_m, atol=TOL_M)
    (finding,) = got.input_findings
    assert "kinarm.c3d" in finding and "description of POINT (160 characters)" in finding and "cut to 127" in finding


@pytest.mark.parametrize("name", ["OFFSET", "SCALE"])
def test_analog_channels_ezc3d_crashes_on_are_left_out_and_the_markers_read(tmp_path, name):
    """ANALOG:OFFSET or ANALOG:SCALE absent while ANALOG:USED > 0 (an old Motion Analysis file names
    them ANALOG:OFFSETS): ezc3d crashes (segmentation fault) on such a file; exubio reads its markers
    without the analog channels, says so, and refuses to read the channels."""
    from exubio.io.c3d import read_c3d_analogs

    traj = make_trajectories(["A", "B", "C"], n_frames=40)

    def analogs(c3d):
        c3d["parameters"]["ANALOG"]["RATE"]["value"] = np.array([1000.0])
        c3d["parameters"]["ANALOG"]["LABELS"]["value"] = ("F1", "F2", "F3", "F4")
        c3d["data"]["analogs"] = np.random.default_rng(1).normal(size=(1, 4, 400))

    path = write_custom(tmp_path / "mac.c3d", traj, edit=analogs)
    data = bytearray(path.read_bytes())
    at = data.index(bytes([len(name), 2]) + name.encode())  # the record of ANALOG (group 2) named so
    data[at + 1 + len(name)] = ord("Q")  # its last letter: the parameter is gone under another name
    path.write_bytes(bytes(data))
    got = read_c3d(path)
    np.testing.assert_allclose(got.positions_m, traj.positions_m, atol=TOL_M)
    (finding,) = got.input_findings
    assert f"ANALOG:USED is 4 but ANALOG:{name} is absent" in finding and "read without them" in finding
    with pytest.raises(InputError, match=rf"mac\.c3d: its analog channels cannot be read: .*ANALOG:{name}"):
        read_c3d_analogs(path)


def test_integer_scale_factors_that_disagree_are_refused(tmp_path):
    """An integer-format file whose header scale (words 7-8) is not its POINT:SCALE: positions would
    differ by their ratio (the old Motion Analysis sample, 2.56), so it is refused naming both."""
    source = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d_vendors" / "sample01_Eb015pi.c3d"
    if not source.is_file():
        pytest.skip(f"{source} not available")
    data = bytearray(source.read_bytes())
    scale = struct.unpack("<f", data[12:16])[0]
    assert scale > 0  # the integer format
    data[12:16] = struct.pack("<f", 2.5 * scale)
    path = tmp_path / "scales.c3d"
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"scales\.c3d: its scale factors disagree: .* differ by a factor 2\.5"):
        read_c3d(path)


def test_a_file_whose_points_are_all_unlabelled_is_refused(tmp_path):
    path = write_custom(tmp_path / "unlabelled.c3d", make_trajectories(["*1", "*2"]))
    with pytest.raises(InputError, match=r"unlabelled\.c3d: none of its 2 points has a label a protocol can name"):
        read_c3d(path)


@pytest.mark.parametrize("name", ["RATIO", "USED"])
def test_a_negative_rotation_count_is_refused_before_ezc3d_sizes_memory_by_it(tmp_path, name):
    """ROTATION:RATIO or USED made negative (a mutated byte, studies/c3d_mutations.py --seed 11: a
    RATIO of -256 had ezc3d ask for 12 GB): refused naming the parameter, before ezc3d reads it."""
    path = write_c3d(tmp_path / "rot.c3d", make_trajectories(["A", "B", "C"], n_frames=30))
    data = bytearray(path.read_bytes())
    group = data.index(b"ROTATION")  # the group record: [length][-id][name]
    ident = -struct.unpack_from("b", data, group - 1)[0]
    at = data.index(bytes([len(name), ident]) + name.encode(), group)  # its record: name, offset word, type, dims
    assert data[at + 2 + len(name) + 2] == 2 and data[at + 2 + len(name) + 3] == 0  # an int16 scalar
    struct.pack_into("<h", data, at + 2 + len(name) + 4, -256)
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=rf"rot\.c3d: .*parameter ROTATION:{name} is -256; expected a count of 0 or more"):
        read_c3d(path)
