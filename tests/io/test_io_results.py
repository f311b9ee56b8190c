"""exubio.io.results: atomic writing, the output folder guard, and exact round trips of the
angle CSV, the OpenSim .mot, the .npz archive, plus strict JSON."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from exubio.errors import InputError
from exubio.io.results import (
    atomic_write,
    prepare_output_dir,
    read_angles_csv,
    read_mot,
    read_npz,
    read_npz_metadata,
    write_angles_csv,
    write_json,
    write_mot,
    write_npz,
)
from exubio.types import FrameStatus, Gap, Reconstruction

NAMES = ("SC_y", "SC_z", "GH_plane", "GH_elev", "EL_x")
HALF_ULP_DEG = 0.5e-6 + 1e-12  # %.6f degrees


def angles(n_frames=25, seed=2):
    rng = np.random.default_rng(seed)
    time = np.arange(n_frames) / 100.0
    q = rng.uniform(-np.pi, np.pi, size=(n_frames, len(NAMES)))
    q[3, 1] = np.nan
    return time, q


def reconstruction(n_frames=12, n_markers=4, seed=3) -> Reconstruction:
    rng = np.random.default_rng(seed)
    k = len(NAMES)
    measured = rng.normal(size=(n_frames, n_markers, 3))
    measured[2:5, 1] = np.nan
    residuals = rng.uniform(0, 0.01, size=(n_frames, n_markers))
    residuals[2:5, 1] = np.nan
    status = np.full(n_frames, FrameStatus.CONVERGED, dtype=np.int8)
    status[7] = FrameStatus.TOO_FEW_MARKERS
    return Reconstruction(
        method="pf",
        time_s=np.arange(n_frames) / 100.0,
        coordinate_names=NAMES,
        q_rad=rng.normal(size=(n_frames, k)),
        qd_rad_s=rng.normal(size=(n_frames, k)),
        qdd_rad_s2=rng.normal(size=(n_frames, k)),
        marker_names=("ARM", "DELT", "EPI_lat", "SCAP_AA")[:n_markers],
        model_points_m=rng.normal(size=(n_frames, n_markers, 3)),
        measured_m=measured,
        residuals_m=residuals,
        constraint=rng.normal(scale=1e-6, size=(n_frames, 2)),
        constraint_velocity=rng.normal(scale=1e-6, size=(n_frames, 2)),
        status=status,
        timings_s={"build": 0.125, "solve": 3.0000001, "total": 3.2},
        info={"iterations": [3, 4, 5], "mean_deflection_m": 0.0012, "note": "ok", "bad": float("nan")},
        gaps=(Gap("DELT", 2, 5), Gap("ARM", 9, 12)),
    )


def assert_same_reconstruction(a: Reconstruction, b: Reconstruction) -> None:
    for name in Reconstruction.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == np.asarray(y).dtype, name
            np.testing.assert_array_equal(x, y, err_msg=name)  # NaN == NaN here
        elif name == "info":
            assert json.dumps(dict(x)) == json.dumps(dict(y))  # NaN-aware
        else:
            assert x == y, name


# ------------------------------------------------------------------------- atomic writing
def test_atomic_write_replaces_the_file(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("old", encoding="utf-8")
    atomic_write(path, lambda tmp: tmp.write_text("new", encoding="utf-8"))
    assert path.read_text(encoding="utf-8") == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_failing_writer_leaves_the_old_file_intact(tmp_path):
    path = tmp_path / "angles.csv"
    path.write_text("old,complete\n", encoding="utf-8")

    def half_then_crash(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write("time_s,half")
            fh.flush()
            assert tmp.stat().st_size > 0  # the half file really exists on disk
            raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError, match="disk on fire"):
        atomic_write(path, half_then_crash)
    assert path.read_text(encoding="utf-8") == "old,complete\n"
    assert [p.name for p in tmp_path.iterdir()] == ["angles.csv"]


def test_temporary_file_is_in_the_target_folder_with_the_target_suffix(tmp_path):
    seen = []
    atomic_write(tmp_path / "fig.png", lambda tmp: seen.append(tmp) or tmp.write_bytes(b"x"))
    atomic_write(tmp_path / "t.c3d", lambda tmp: seen.append(tmp) or tmp.write_bytes(b"x"), temp_suffix=".bin")
    assert seen[0].parent == tmp_path and seen[0].suffix == ".png" and seen[0].name.startswith(".")
    assert seen[1].suffix == ".bin"


def test_atomic_write_gives_normal_permissions(tmp_path):
    reference = tmp_path / "ref"
    reference.write_text("x", encoding="utf-8")
    path = atomic_write(tmp_path / "new.txt", lambda tmp: tmp.write_text("x", encoding="utf-8"))
    assert path.stat().st_mode & 0o777 == reference.stat().st_mode & 0o777


def test_atomic_write_into_missing_folder(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        atomic_write(tmp_path / "no" / "x.txt", lambda tmp: tmp.write_text("x", encoding="utf-8"))


def test_os_errors_become_input_errors_naming_the_path(tmp_path):
    def fails(tmp: Path) -> None:
        raise PermissionError("denied")

    with pytest.raises(InputError, match=r"x\.txt: cannot write \(denied\)"):
        atomic_write(tmp_path / "x.txt", fails)
    assert not any(tmp_path.iterdir())


# ------------------------------------------------------------------------- output folder
def test_prepare_output_dir_creates_nested_folders(tmp_path):
    out = prepare_output_dir(tmp_path / "a" / "b", ["P01_pf", "summary.json"], overwrite=False)
    assert out.is_dir() and out == tmp_path / "a" / "b"


def test_prepare_output_dir_refuses_existing_results(tmp_path):
    (tmp_path / "P01_pf.csv").write_text("keep me", encoding="utf-8")
    (tmp_path / "P01_pfx.csv").write_text("unrelated", encoding="utf-8")
    with pytest.raises(InputError, match=r"P01_pf\.csv.*already exists.*--overwrite.*another output folder"):
        prepare_output_dir(tmp_path, ["P01_pf", "summary.json"], overwrite=False)
    prepare_output_dir(tmp_path, ["P01_pfx.mot", "P01_ls"], overwrite=False)  # no clash
    (tmp_path / "summary.json").write_text("{}", encoding="utf-8")
    with pytest.raises(InputError, match=r"summary\.json"):
        prepare_output_dir(tmp_path, ["summary.json"], overwrite=False)


def test_prepare_output_dir_with_overwrite_deletes_nothing(tmp_path):
    (tmp_path / "P01_pf.csv").write_text("keep me", encoding="utf-8")
    prepare_output_dir(tmp_path, ["P01_pf"], overwrite=True)
    assert (tmp_path / "P01_pf.csv").read_text(encoding="utf-8") == "keep me"


def test_prepare_output_dir_refuses_a_file(tmp_path):
    (tmp_path / "out").write_text("", encoding="utf-8")
    with pytest.raises(InputError, match="existing file"):
        prepare_output_dir(tmp_path / "out", ["x"], overwrite=True)


# ------------------------------------------------------------------------- CSV
def test_csv_round_trip_to_the_printed_precision(tmp_path):
    time, q = angles()
    path = write_angles_csv(tmp_path / "a.csv", time, NAMES, q)
    t2, names, q2 = read_angles_csv(path)
    assert names == NAMES
    np.testing.assert_allclose(t2, time, rtol=0, atol=0.5e-6)
    np.testing.assert_array_equal(np.isnan(q2), np.isnan(q))
    np.testing.assert_allclose(np.degrees(q2), np.degrees(q), rtol=0, atol=HALF_ULP_DEG, equal_nan=True)


def test_csv_is_plain_with_degrees(tmp_path):
    time = np.array([0.0, 0.01])
    q = np.radians([[90.0, -45.5], [1.25, 0.0]])
    path = write_angles_csv(tmp_path / "a.csv", time, ("GH_elev", "EL_x"), q)
    assert path.read_text(encoding="utf-8").splitlines() == [
        "time_s,GH_elev,EL_x",
        "0.000000,90.000000,-45.500000",
        "0.010000,1.250000,0.000000",
    ]
    table = np.genfromtxt(path, delimiter=",", names=True)
    assert table.dtype.names == ("time_s", "GH_elev", "EL_x")


@pytest.mark.parametrize(
    "names, q_shape, message",
    [(NAMES[:2], (25, 5), r"shape \(25, 5\), expected .* \(25, 2\)"), (("a,b",), (25, 1), "'a,b'"),
     (("x", "x"), (25, 2), "duplicate")],
)
def test_csv_refuses_inconsistent_input(tmp_path, names, q_shape, message):
    time, _ = angles()
    with pytest.raises(InputError, match=message):
        write_angles_csv(tmp_path / "a.csv", time, names, np.zeros(q_shape))
    assert not any(tmp_path.iterdir())


def test_read_csv_errors_name_file_and_line(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("time_s,a\n0,1\n0.01,2,3\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"bad\.csv: line 3: 3 columns, expected 2"):
        read_angles_csv(path)
    path.write_text("t,a\n0,1\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"bad\.csv: line 1: expected a header starting with 'time_s'"):
        read_angles_csv(path)


# ------------------------------------------------------------------------- .mot
def test_mot_round_trip_and_header(tmp_path):
    time, q = angles()
    path = write_mot(tmp_path / "a.mot", time, NAMES, q, name="P01_ABD01_pf")
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[:7] == [
        "P01_ABD01_pf", "version=1", "nRows=25", f"nColumns={len(NAMES) + 1}", "inDegrees=yes", "endheader",
        "time\t" + "\t".join(NAMES),
    ]
    assert len(lines) == 7 + 25
    t2, names, q2 = read_mot(path)
    assert names == NAMES
    np.testing.assert_allclose(t2, time, rtol=0, atol=0.5e-6)
    np.testing.assert_allclose(np.degrees(q2), np.degrees(q), rtol=0, atol=HALF_ULP_DEG, equal_nan=True)


def test_read_mot_in_radians_and_count_check(tmp_path):
    path = tmp_path / "r.mot"
    path.write_text("x\nversion=1\nnRows=2\nnColumns=2\ninDegrees=no\nendheader\ntime\ta\n0\t1.5\n0.1\t-2\n", encoding="utf-8")
    t, names, q = read_mot(path)
    assert names == ("a",)
    np.testing.assert_array_equal(q[:, 0], [1.5, -2.0])
    path.write_text("x\nnRows=3\nendheader\ntime\ta\n0\t1.5\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"r\.mot: header says nrows=3 but the table has 1"):
        read_mot(path)
    path.write_text("x\ntime\ta\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"r\.mot: not a \.mot file: no 'endheader'"):
        read_mot(path)


# ------------------------------------------------------------------------- .npz
def test_npz_round_trip_is_exact(tmp_path):
    rec = reconstruction()
    meta = {"trial": "ABD01.trc", "cutoff_hz": 2.0, "protocol": {"markers": ["ARM", "DELT"]}, "seed": np.int64(4)}
    path = write_npz(tmp_path / "r.npz", rec, metadata=meta)
    got = read_npz(path)
    assert_same_reconstruction(rec, got)
    assert read_npz_metadata(path) == {"trial": "ABD01.trc", "cutoff_hz": 2.0,
                                       "protocol": {"markers": ["ARM", "DELT"]}, "seed": 4}
    assert math.isnan(got.info["bad"])


def test_npz_is_plain_numpy_without_pickle(tmp_path):
    rec = reconstruction()
    path = write_npz(tmp_path / "r.npz", rec, metadata={})
    with np.load(path, allow_pickle=False) as data:
        assert list(data["coordinate_names"]) == list(NAMES)
        assert data["q_rad"].shape == (12, len(NAMES))
        assert json.loads(str(data["metadata_json"])) == {}
        assert list(data["gap_markers"]) == ["DELT", "ARM"]


def test_npz_without_gaps_or_info(tmp_path):
    rec = reconstruction()
    rec = Reconstruction(**{**rec.__dict__, "gaps": (), "info": {}, "timings_s": {}})
    got = read_npz(write_npz(tmp_path / "r.npz", rec, metadata={}))
    assert got.gaps == () and dict(got.info) == {} and dict(got.timings_s) == {}


def test_read_npz_errors(tmp_path):
    with pytest.raises(InputError, match=r"none\.npz: file not found"):
        read_npz(tmp_path / "none.npz")
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    with pytest.raises(InputError, match=r"other\.npz: no entry '.*' \(not an exubio result\?\)"):
        read_npz(other)
    junk = tmp_path / "junk.npz"
    junk.write_text("not a zip", encoding="utf-8")
    with pytest.raises(InputError, match=r"junk\.npz: not a readable \.npz"):
        read_npz(junk)


# ------------------------------------------------------------------------- JSON
def test_write_json_is_strict_and_converts_numpy(tmp_path):
    data = {
        "n": np.int32(3),
        "x": np.float64(0.5),
        "nan": float("nan"),
        "arr": np.array([1.0, np.nan, np.inf]),
        "nested": {"t": (1, 2), "ok": np.bool_(True), "path": Path("a/b")},
        "status": FrameStatus.NOT_CONVERGED,
    }
    path = write_json(tmp_path / "summary.json", data)
    text = path.read_text(encoding="utf-8")

    def refuse(constant):
        raise AssertionError(f"non-standard JSON constant {constant}")

    loaded = json.loads(text, parse_constant=refuse)
    assert loaded == {"n": 3, "x": 0.5, "nan": None, "arr": [1.0, None, None],
                      "nested": {"t": [1, 2], "ok": True, "path": "a/b"}, "status": 1}
    assert text.startswith('{\n  "n": 3,') and text.endswith("}\n")


def test_write_json_refuses_unknown_types_without_touching_the_file(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text("{}", encoding="utf-8")
    with pytest.raises(TypeError, match="object"):
        write_json(path, {"x": object()})
    assert path.read_text(encoding="utf-8") == "{}"
    assert os.listdir(tmp_path) == ["summary.json"]


def test_read_csv_numbers_are_float_of_each_cell(tmp_path):
    """The compiled reader gives the doubles float() gives (every digit, sign of zero, nan, inf,
    subnormals), blank lines skipped; a line it refuses is named by the fallback."""
    from exubio.io.results import read_angles_csv

    rng = np.random.default_rng(7)
    cells = [["-0.000000", "nan", "inf", "-inf", "1e-320", "4.9e-324", " 2.5 ", "179.9999995"]]
    cells += [[f"{x:.6f}" for x in rng.normal(0, 90, 8)] for _ in range(300)]
    cells += [[repr(float(x)) for x in rng.normal(0, 1e-3, 8)] for _ in range(300)]
    text = "time_s," + ",".join(f"a{j}" for j in range(7)) + "\n"
    text += "\n".join(",".join(r) for r in cells[:200]) + "\n\n" + "\n".join(",".join(r) for r in cells[200:]) + "\n"
    path = tmp_path / "x.csv"
    path.write_text(text, encoding="utf-8")
    t, names, values = read_angles_csv(path)
    want = np.array([[float(c) for c in r] for r in cells])
    assert np.array_equal(t, want[:, 0], equal_nan=True) and np.array_equal(np.signbit(t), np.signbit(want[:, 0]))
    assert np.array_equal(values, np.radians(want[:, 1:]), equal_nan=True)
