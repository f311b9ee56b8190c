"""exubio.io.trc (and the suffix dispatch of exubio.io.trial): real OpenSim files, round trips,
missing cells, and InputErrors that name the file and line of a malformed TRC."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError
from exubio.io.trc import read_trc, write_trc
from exubio.io.trial import read_trial
from exubio.types import Trajectories

SHARED_TRC = Path(__file__).resolve().parents[3] / "shared" / "data" / "trc"
TSM_LABELS = ("gu", "centelbow", "EpL", "centpxt8", "centijc7", "ij", "ts", "aa", "ai")
HEADER = (
    "PathFileType\t4\t(X/Y/Z)\tsmall.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "{rate}\t{rate}\t{n_frames}\t2\t{units}\t{rate}\t1\t{n_frames}\n"
    "Frame#\tTime\tA\t\t\tB\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    "\n"
)
ROWS = (
    "1\t0.5\t1\t2\t3\t4\t5\t6\n"
    "2\t0.75\t\t\t\t4.5\t5.5\t6.5\n"  # A missing (empty cells)
    "3\t1.0\t1.5\tNaN\t3.5\t4\t5\t6\t\t\n"  # NaN cell, trailing empty cells
)


def shared(name: str) -> Path:
    path = SHARED_TRC / name
    if not path.is_file():
        pytest.skip(f"shared data file {path} not available")
    return path


def small_trc(tmp_path: Path, *, rows=ROWS, units="mm", rate="4", n_frames=3, header=HEADER) -> Path:
    path = tmp_path / "small.trc"
    path.write_text(header.format(rate=rate, n_frames=n_frames, units=units) + rows, encoding="utf-8")
    return path


def random_trajectories(n_frames=40, labels=("gu", "EpL", "ts"), rate=120.0, seed=1) -> Trajectories:
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-0.5, 0.5, size=(n_frames, len(labels), 3))
    pos[3:7, 1] = np.nan
    pos[10, 2, 1] = np.nan
    return Trajectories(labels, pos, rate, np.arange(n_frames) / rate)


# ------------------------------------------------------------------------- real files
@pytest.mark.parametrize("name, n_frames", [("tsm_rmr_ABD01.trc", 1091), ("tsm_rmr_FLX01.trc", 794)])
def test_real_files_fingerprint(name, n_frames):
    traj = read_trc(shared(name))
    assert traj.positions_m.shape == (n_frames, 9, 3)
    assert traj.labels == TSM_LABELS
    assert traj.rate_hz == 100.0 and traj.units_in_file == "mm"
    np.testing.assert_allclose(traj.time_s, np.arange(n_frames) / 100.0, atol=1e-12)
    assert not np.isnan(traj.positions_m).any()
    np.testing.assert_array_equal(traj.marker("ij"), 0.0)  # the thorax origin
    norms = np.linalg.norm(traj.positions_m, axis=2)
    assert 0.05 < np.median(norms) < 1.0 and norms.max() < 1.0  # metres


def test_real_file_values_in_metres():
    traj = read_trc(shared("tsm_rmr_ABD01.trc"))
    np.testing.assert_allclose(traj.marker("ai")[0], [-0.161221, -0.079682, 0.06035], rtol=0, atol=1e-12)
    np.testing.assert_allclose(traj.marker("ai")[-1], [-0.14382, -0.080366, 0.043984], rtol=0, atol=1e-12)


def test_real_file_round_trip(tmp_path):
    traj = read_trc(shared("tsm_rmr_FLX01.trc"))
    got = read_trc(write_trc(tmp_path / "copy.trc", traj))
    assert got.labels == traj.labels and got.rate_hz == traj.rate_hz
    np.testing.assert_allclose(got.positions_m, traj.positions_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.time_s, traj.time_s, rtol=0, atol=1e-12)


# ------------------------------------------------------------------------- small files
def test_missing_cells_are_nan_and_time_comes_from_the_file(tmp_path):
    traj = read_trc(small_trc(tmp_path))
    assert traj.labels == ("A", "B") and traj.rate_hz == 4.0
    np.testing.assert_array_equal(traj.time_s, [0.5, 0.75, 1.0])
    expected_mm = np.array(
        [[[1, 2, 3], [4, 5, 6]], [[np.nan] * 3, [4.5, 5.5, 6.5]], [[1.5, np.nan, 3.5], [4, 5, 6]]]
    )
    np.testing.assert_allclose(traj.positions_m, expected_mm * 1e-3, rtol=0, atol=1e-15)
    assert traj.source == str(tmp_path / "small.trc")


@pytest.mark.parametrize("units, factor", [("mm", 1e-3), ("cm", 1e-2), ("m", 1.0), ("MM", 1e-3)])
def test_units_from_the_header(tmp_path, units, factor):
    traj = read_trc(small_trc(tmp_path, units=units))
    assert traj.units_in_file == units.lower()
    np.testing.assert_allclose(traj.marker("B")[0], np.array([4, 5, 6]) * factor, rtol=1e-15)


@pytest.mark.parametrize("units", ["mm", "cm", "m"])
def test_round_trip_to_the_printed_precision(tmp_path, units):
    traj = random_trajectories()
    got = read_trc(write_trc(tmp_path / "rt.trc", traj, units=units))
    assert got.labels == traj.labels and got.units_in_file == units and got.rate_hz == 120.0
    np.testing.assert_array_equal(np.isnan(got.positions_m), np.isnan(traj.positions_m))
    # 1e-9 m printed resolution: rounding error <= 0.5e-9 m
    np.testing.assert_allclose(got.positions_m, traj.positions_m, rtol=0, atol=0.51e-9, equal_nan=True)
    np.testing.assert_allclose(got.time_s, traj.time_s, rtol=1e-9, atol=0)


def test_written_file_layout(tmp_path):
    traj = random_trajectories(n_frames=12, labels=("a", "b", "c"))
    path = write_trc(tmp_path / "layout.trc", traj)
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\tlayout.trc"
    assert lines[1].split("\t")[:5] == ["DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units"]
    assert lines[2].split("\t")[:5] == ["120", "120", "12", "3", "mm"]
    assert lines[3] == "Frame#\tTime\ta\t\t\tb\t\t\tc\t\t"
    assert lines[4] == "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\tX3\tY3\tZ3"
    first = lines[6].split("\t")
    assert first[:2] == ["1", "0"] and len(first) == 11
    assert first[2] == f"{traj.positions_m[0, 0, 0] * 1e3:.6f}"  # millimetres, 6 decimals
    gap_row = lines[6 + 3].split("\t")  # frame 4: marker b missing -> empty cells
    assert gap_row[5:8] == ["", "", ""] and gap_row[2] != ""
    assert [p.name for p in tmp_path.iterdir()] == ["layout.trc"]


def test_write_refuses_unknown_units_and_bad_labels(tmp_path):
    with pytest.raises(InputError, match="'ft'"):
        write_trc(tmp_path / "x.trc", random_trajectories(), units="ft")
    traj = random_trajectories(labels=("ok", "with\ttab", "c"))
    with pytest.raises(InputError, match="with\\\\ttab"):
        write_trc(tmp_path / "x.trc", traj)
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------------------- malformed files
def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="nope.trc: file not found"):
        read_trc(tmp_path / "nope.trc")


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(header="Bogus\n" + HEADER.split("\n", 1)[1]), r"line 1: expected 'PathFileType"),
        (dict(units="furlong"), r"line 3: Units is 'furlong', expected one of \['cm', 'm', 'mm'\]"),
        (dict(rate="fast"), r"line 3: DataRate/NumFrames/NumMarkers must be numbers"),
        (dict(rate="0"), r"line 3: expected DataRate > 0"),
        (dict(rate="1e9"), r"line 3: DataRate is 1e\+09 Hz \(above 100000 Hz"),
        (dict(rows=""), r"no data rows after line 5"),
        (dict(header=HEADER.replace("\tB\t\t", "\tB\t\t\tC\t\t")),
         r"line 4: 3 marker labels, but line 3 says NumMarkers=2 and the first data row has 8 columns \(2 markers\)"),
        (dict(header=HEADER.replace("Frame#", "Frame")), r"line 4: expected 'Frame#"),
        (dict(rows=ROWS + "4\t1.25\t1\t2\t3\t4\t5\n"), r"line 10: 7 columns, expected 8"),
        (dict(rows=ROWS + "4\t1.25\t1\t2\t3\t4\t5\t6\t7\n"), r"line 10: 9 columns, expected 8"),
        (dict(rows=ROWS + "4\t1.25\t1\t2\t3\t4\tfive\t6\n"), r"line 10: 'five' is not a number"),
        (dict(rows=ROWS + "4\t\t1\t2\t3\t4\t5\t6\n"), r"line 10: the Time cell is empty"),
    ],
    ids=["line1", "units", "rate-text", "rate-zero", "rate-1e9", "no-rows", "labels", "frame-col", "short-row",
         "long-row", "text-cell", "no-time"],
)
def test_malformed_files_name_file_and_line(tmp_path, kwargs, message):
    path = small_trc(tmp_path, **kwargs)
    with pytest.raises(InputError, match=r"small\.trc: " + message):
        read_trc(path)


@pytest.mark.parametrize("n_frames", [2, 4, 23])
def test_num_frames_contradicted_by_the_rows_is_read_from_the_rows_with_a_finding(tmp_path, caplog, n_frames):
    """As OpenSim reads them: the rows are the data, the header's NumFrames a count that can be
    wrong (4 of 15 published thoracoscapular files are off by 1 or 18 rows); the header value is named
    in a logged warning and in Trajectories.input_findings, which the results carry."""
    path = small_trc(tmp_path, n_frames=n_frames)
    with caplog.at_level("WARNING", logger="exubio.io.trc"):
        traj = read_trc(path)
    assert traj.n_frames == 3 and traj.time_s.tolist() == [0.5, 0.75, 1.0]
    assert len(traj.input_findings) == 1
    finding = traj.input_findings[0]
    assert f"NumFrames is {n_frames}" in finding and "3 data rows" in finding and "small.trc" in finding
    assert finding in caplog.text
    assert read_trc(small_trc(tmp_path, n_frames=3)).input_findings == ()


def test_too_short_header(tmp_path):
    path = tmp_path / "short.trc"
    path.write_text("PathFileType\t4\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"short\.trc: not a TRC file"):
        read_trc(path)


def test_binary_file_is_an_input_error(tmp_path):
    path = tmp_path / "bin.trc"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match=r"bin\.trc"):
        read_trc(path)


# ------------------------------------------------------------------------- read_trial
def test_read_trial_dispatches_on_suffix_case_insensitively(tmp_path):
    src = small_trc(tmp_path)
    upper = src.rename(tmp_path / "SMALL.TRC")
    traj = read_trial(upper)
    assert traj.labels == ("A", "B") and traj.source == str(upper)


def test_read_trial_refuses_other_suffixes_listing_the_accepted_ones(tmp_path):
    path = tmp_path / "trial.csv"
    path.write_text("time,x\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"trial\.csv: unsupported.*'\.csv'.*\['\.c3d', '\.trc'\]"):
        read_trial(path)


def test_read_trial_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"gone\.trc: file not found"):
        read_trial(tmp_path / "gone.trc")
    with pytest.raises(InputError, match=r"gone\.c3d: file not found"):
        read_trial(tmp_path / "gone.c3d")


# ------------------------------------------------------------------------- header against rows, labels
def _header_and_rows(labels, n_declared, rows):
    return ("PathFileType\t4\t(X/Y/Z)\tsmall.trc\n"
            "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
            f"4\t4\t{len(rows)}\t{n_declared}\tmm\t4\t1\t{len(rows)}\n"
            "Frame#\tTime" + "".join(f"\t{label}\t\t" for label in labels) + "\n"
            "\t" + "".join(f"\tX{i}\tY{i}\tZ{i}" for i in range(1, len(labels) + 1)) + "\n\n"
            + "".join(f"{i + 1}\t{i / 4}\t" + "\t".join(f"{v:g}" for v in row) + "\n" for i, row in enumerate(rows)))


def test_num_markers_below_the_labels_and_rows_is_read_from_them_with_a_finding(tmp_path, caplog):
    """A Motion Analysis Cortex TRC listing 34 labels under NumMarkers=28: the labels of line 4 and
    the rows' columns agree, so they are read, and the header's count is named."""
    labels = [f"M{k}" for k in range(34)]
    rows = np.arange(3 * 34 * 3, dtype=float).reshape(3, 34 * 3)
    path = tmp_path / "cortex.trc"
    path.write_text(_header_and_rows(labels, 28, rows), encoding="utf-8")
    with caplog.at_level("WARNING", logger="exubio.io.trc"):
        traj = read_trc(path)
    assert traj.labels == tuple(labels) and traj.n_frames == 3
    np.testing.assert_allclose(traj.positions_m.reshape(3, -1), rows * 1e-3)
    (finding,) = traj.input_findings
    assert "NumMarkers is 28" in finding and "34 marker labels" in finding and "cortex.trc" in finding
    assert finding in caplog.text


def test_duplicate_label_keeps_the_first_marker_with_samples_and_says_so(tmp_path):
    rows = [[np.nan, np.nan, np.nan, np.nan, np.nan, np.nan, 7, 8, 9, 1, 2, 3],
            [np.nan, np.nan, np.nan, 40, 50, 60, 7, 8, 9, 1, 2, 3]]
    path = tmp_path / "dup.trc"
    path.write_text(_header_and_rows(["A", "B", "A", "A"], 4, rows).replace("nan", ""), encoding="utf-8")
    traj = read_trc(path)
    assert traj.labels == ("B", "A") and traj.ignored_labels == ("A", "A")
    np.testing.assert_allclose(traj.marker("A"), [[7e-3, 8e-3, 9e-3]] * 2)  # marker 3: marker 1 has no sample
    (finding,) = traj.input_findings
    assert "3 markers are labelled 'A'" in finding and "kept marker 3, the first with samples" in finding
    assert "10.4 mm" in finding  # marker 4 lies 10.4 mm from marker 3


def test_empty_label_in_its_place_is_left_out_with_a_finding(tmp_path):
    rows = [[1, 2, 3, 4, 5, 6], [1, 2, 3, 4, 5, 6]]
    path = tmp_path / "empty.trc"
    path.write_text(_header_and_rows(["A", ""], 2, rows), encoding="utf-8")
    traj = read_trc(path)
    assert traj.labels == ("A",)
    (finding,) = traj.input_findings
    assert "marker 2 (columns 6-8) has an empty label (2 samples)" in finding


def test_no_label_at_all_is_refused(tmp_path):
    path = tmp_path / "none.trc"
    path.write_text(_header_and_rows(["", ""], 2, [[1, 2, 3, 4, 5, 6]]).replace(
        "Frame#\tTime\t\t\t\t\t\t", "Frame#\tTime\t"), encoding="utf-8")
    with pytest.raises(InputError, match=r"none\.trc: line 4: none of its 2 markers has a label"):
        read_trc(path)
