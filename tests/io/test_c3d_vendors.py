"""Every file of the public C3D test suite (../shared/data/c3d_vendors: the c3d.org samples and
BTK's cases, see its SOURCES.md), one test each: read with the points, frames and rate ezc3d reads
(cross-checked against ezc3d's own reading of the file, positions included) and the input findings
that name what was read around, or refused with the reason named. Skipped where the folder is absent.

The expected counts come from ezc3d 1.7.2 and the files' readmes, not from exubio."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError
from exubio.io.c3d import read_c3d, strip_prefix

VENDORS = Path(__file__).resolve().parents[3] / "shared" / "data" / "c3d_vendors"

# file: (points ezc3d reads, of which exubio reads, frames, rate Hz, words every finding together holds)
READ = {
    "others_561xxa01_anonym.C3D": (34, 26, 361, 100.0, ["'SUBJECT:PELVIS WIDTH'", "POINT:UNITS is absent",
                                                        "2 points are labelled 'r should'", "kept point 1, the first"]),
    "others_ADemo1_rewrite_c3d_pc_float.c3d": (24, 24, 512, 200.0, []),
    "others_ADemo1_rewrite_c3d_pc_integer.c3d": (24, 24, 512, 200.0, []),
    "others_Gait.c3d": (33, 27, 487, 100.0, ["2 points are labelled 'RKNE'", "kept point 12, the first"]),
    "others_MyCube.c3d": (14, 14, 1, 50.0, []),
    "others_parameterOverflow.c3d": (142, 118, 101, 100.0, ["'PROCESSING:MARKER DIAMETER'",
                                                            "declares 46 block(s)", "records run to byte 24640"]),
    **{f"sample01_Eb015{v}.c3d": (26, 26, 450, 50.0, []) for v in ("pi", "pr", "vi", "vr")},
    **{f"sample01_Eb015{v}.c3d": (26, 26, 450, 50.0, ["processor format SGI/MIPS", "copy in Intel byte order"])
       for v in ("si", "sr")},
    "sample22_BKINtechnologies.c3d": (2, 2, 5065, 1000.0, ["description of EXPERIMENT:SESSION (163 characters)",
                                                           "cut to 127", "'TP_TABLE:(UNUSED)'"]),
    # PhoeniX: ANALOG:OFFSET stored as floats, which ezc3d refuses; the counts and rates are the
    # header's words 2, 4-5 and 11-12 (read here from the bytes), the positions its float data block in mm
    "sample13_Dance.c3d": (40, 40, 499, 65.0533447265625, ["ANALOG:OFFSET is stored as floating-point numbers",
                                                           "markers are read without them", "declares 3 block(s)"]),
    "sample13_golfswing.c3d": (29, 29, 514, 107.5268783569336, ["ANALOG:OFFSET is stored as floating-point numbers",
                                                                "markers are read without them", "declares 3 block(s)"]),
    **{f"sample02_{v}.{'C3D' if v == 'DEC_INT' else 'c3d'}": (36, 36, 89, 50.0, [])
       for v in ("DEC_INT", "Dec_real", "pc_int", "pc_real")},
    "sample04_sub_labels.c3d": (114, 114, 333, 60.0, []),
    **{f"sample08_TEST{v}PI.c3d": (26, 26, 450, 50.0, []) for v in "ABCD"},
    "sample09_PlugInC3D.c3d": (86, 86, 281, 60.0, []),
    "sample15_FP1.C3D": (8, 8, 480, 60.0, ["declares 3 block(s)", "POINT:UNITS is 'mete'; read as 'm'"]),
    "sample21_sample21.c3d": (14, 10, 574, 60.0, ["2 points are labelled 'RTHI'", "kept point 4, the first"]),
    "sample24_MotionMonitorC3D.c3d": (8, 7, 840, 140.0, ["point 1 has an empty label"]),
    "sample28_standing.C3D": (38, 28, 200, 100.0, ["POINT:UNITS is absent", "2 points are labelled 'c7'"]),
    "sample28_type1.C3D": (28, 28, 296, 100.0, []),
}
# SGI/MIPS files ezc3d does not read: each is compared with its Intel twin of the same recording
# (c3d.org made them from the same data) as ezc3d reads that
TWIN = {"sample01_Eb015si.c3d": "sample01_Eb015pi.c3d", "sample01_Eb015sr.c3d": "sample01_Eb015pr.c3d"}
# file: words the refusal holds (ezc3d refuses these too, or reads no 3-D point from them)
REFUSED = {
    "others_1123x01EMG.c3d": ["no 3-D point: POINT:USED is 0", "analog channels only"],
    "others_Empty.c3d": ["the file is empty (0 bytes)"],
    "others_badParameterOffset.c3d": ["record POINT:LABELS", "offset to the next record"],
    "others_mocap36.c3d": ["record POINT:LABELS", "offset to the next record"],
    # its POINT:LABELS record's offset is stored little-endian in a big-endian file (319 as 16129)
    "sample02_sgi_int.c3d": ["record POINT:LABELS", "offset to the next record is 16129"],
    # integer coordinates under two scales: 0.0215 (POINT:SCALE) gives a shoulder width of 158 mm
    "sample06_MACsample.c3d": ["scale factors disagree", "POINT:SCALE is 0.0215412", "0.0551136", "factor 2.56"],
    "sample18_bad_parameter_section.c3d": ["record EVENT:LABELS", "offset to the next record"],
    "sample20_phasespace_sample.c3d": ["no 3-D point can be read", "declares 40 points", "no POINT parameters"],
}
ALL = sorted({**READ, **REFUSED})
FLOAT_BLOCK = {"sample22_BKINtechnologies.c3d": 1.0, "sample13_Dance.c3d": 1e-3, "sample13_golfswing.c3d": 1e-3}
"""Files ezc3d cannot read, checked against their float data block: POINT:UNITS in metres."""


def _file(name: str) -> Path:
    path = VENDORS / name
    if not path.is_file():
        pytest.skip(f"{path} not available")
    return path


def test_every_file_of_the_folder_has_one_expectation():
    if not VENDORS.is_dir():
        pytest.skip(f"{VENDORS} not available")
    on_disk = sorted(p.name for p in VENDORS.iterdir() if p.suffix.lower() == ".c3d")
    assert on_disk == ALL


@pytest.mark.parametrize("name", ALL)
def test_vendor_file(name):
    path = _file(name)
    if name in REFUSED:
        with pytest.raises(InputError) as refusal:
            read_c3d(path)
        message = str(refusal.value)
        assert message.startswith(str(path)) and "Traceback" not in message
        for words in REFUSED[name]:
            assert words in message, (words, message)
        return
    n_points, n_read, n_frames, rate, words = READ[name]
    traj = read_c3d(path)
    assert (traj.n_markers, traj.n_frames, traj.rate_hz) == (n_read, n_frames, rate)
    assert len(traj.ignored_labels) == n_points - n_read
    found = "\n".join(traj.input_findings)
    for w in words:
        assert w in found, (w, found)
    if not words:
        assert traj.input_findings == ()
    if name in FLOAT_BLOCK:  # ezc3d cannot read it: the data block, read here
        _same_as_float_block(path, traj, FLOAT_BLOCK[name])
        return
    _same_as_ezc3d(_file(TWIN.get(name, name)), traj, n_points)


def _same_as_float_block(path: Path, traj, unit_m: float) -> None:
    """Positions are the file's float data block as this test reads it from the raw bytes (header
    words 2, 3 and 9: points, analog words per frame, first data block; in the unit POINT:UNITS
    says, ``unit_m`` metres; a negative residual word is missing), and the frame count and rate are
    the header's (words 4-5, 11-12)."""
    header = path.read_bytes()[:512]
    first, last = np.frombuffer(header, "<u2", 2, 6)
    assert (traj.n_frames, traj.rate_hz) == (int(last) - int(first) + 1, float(np.frombuffer(header, "<f4", 1, 20)[0]))
    n_points, n_analog = np.frombuffer(header, "<u2", 2, 2)
    start = (int(np.frombuffer(header, "<u2", 1, 16)[0]) - 1) * 512
    words = 4 * int(n_points) + int(n_analog)
    block = np.fromfile(path, "<f4", traj.n_frames * words, offset=start).reshape(traj.n_frames, words)
    xyzr = block[:, : 4 * int(n_points)].reshape(traj.n_frames, int(n_points), 4).astype(float)
    expected = np.where((xyzr[..., 3] < 0)[..., None], np.nan, xyzr[..., :3] * unit_m)
    np.testing.assert_array_equal(traj.positions_m, expected)


def _same_as_ezc3d(path: Path, traj, n_points: int) -> None:
    """Frames, rate and, for every label exubio read, the positions (metres, NaN where the residual
    is negative) are ezc3d's own reading of the file."""
    import ezc3d

    c3d = ezc3d.c3d(str(path))
    points = c3d["data"]["points"]
    assert points.shape[1:] == (n_points, traj.n_frames)
    assert c3d["header"]["points"]["frame_rate"] == traj.rate_hz
    unit = str((c3d["parameters"]["POINT"].get("UNITS", {}).get("value") or ["mm"])[0]).strip().lower()
    scale = 1.0 if unit.startswith("met") or unit == "m" else {"mm": 1e-3, "cm": 1e-2}.get(unit, 1e-3)
    labels = [strip_prefix(str(v)) for v in c3d["parameters"]["POINT"]["LABELS"]["value"]]
    residual = c3d["data"]["meta_points"]["residuals"][0]
    for k, label in enumerate(traj.labels):
        columns = [c for c, raw in enumerate(labels) if raw == label]
        expected = points[:3].transpose(2, 1, 0)[:, columns[0]] * scale
        if len(columns) > 1:  # the first with samples
            column = next(c for c in columns if np.isfinite(traj.positions_m[:, k]).any()
                          and np.allclose(points[:3, c].T * scale, traj.positions_m[:, k], equal_nan=True))
            assert column == next(c for c in columns if (residual[c] >= 0).any())
            continue
        expected = np.where((residual[columns[0]] < 0)[:, None], np.nan, expected)
        np.testing.assert_allclose(traj.positions_m[:, k], expected, atol=1e-9, rtol=1e-6)
