"""External loads in the joint moments (issue 36 item 3): at a static posture a known force and free
moment on the hand change the GH moment by exactly -((r - GH) x F + M) and every generalized force
by its axis' share of the same wrench about its joint (computed here from the model's points and
axes, not by exubio.dynamics); the same load given in the lab, thorax or segment frame gives the
same moments; `exubio reconstruct --loads` reads, filters and resamples a file and says so in the
moments file; every bad file is refused with exit 2 naming the file and the column."""
import numpy as np
import pytest

from exubio.cli import main
from exubio.dynamics.inertia import isb_segment_frames
from exubio.dynamics.loads import ExternalLoad
from exubio.dynamics.moments import joint_moments
from exubio.dynamics.moments_file import read_moments_csv
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.prep.loads import LOAD_COLUMNS, read_loads_csv, resample_load

MASS = 70.0


@pytest.fixture(scope="module")
def model():
    return load_model(body_mass_kg=MASS)


def _static(model, n=5):
    q = np.zeros((n, model.n_coordinates))
    names = model.coordinate_names
    q[:, names.index("elbow_flexion")] = np.radians(70)
    q[:, names.index("pronation")] = np.radians(30)
    q[:, names.index("wrist_flexion")] = np.radians(10)
    z = np.zeros_like(q)
    return q, z, z


def test_a_known_load_changes_the_moments_by_r_cross_f_plus_m(model):
    q, qd, qdd = _static(model)
    n = q.shape[0]
    F, M = np.array([5.0, -20.0, 8.0]), np.array([0.3, -0.7, 1.1])
    point = np.array([0.01, -0.05, 0.02])  # in the hand's model frame
    load = ExternalLoad("hand", "thorax", np.tile(F, (n, 1)), np.tile(M, (n, 1)), np.tile(point, (n, 1)), "test")
    base = joint_moments(model, q, qd, qdd)
    loaded = joint_moments(model, q, qd, qdd, loads=[load])
    # independent: the point and the joint centres from the model's kinematics
    kin = Kinematics(model)
    fr = kin.frames(q)
    hand = model.segment_index("hand")
    r = fr.p[0, hand] + fr.R[0, hand] @ point
    hum = model.segment_index("humerus")
    dM_gh = -(np.cross(r - fr.p[0, hum], F) + M)  # thorax frame, about GH
    A = isb_segment_frames(model)["humerus"][1]
    expect = (fr.R[0, hum] @ A).T @ dM_gh
    got = np.array([loaded.column(f"GH_{a}_moment_Nm")[0] - base.column(f"GH_{a}_moment_Nm")[0] for a in "XYZ"])
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-10)
    for j, name in enumerate(model.coordinate_names):  # every generalized force: its axis' share
        s = kin.coordinate_segment[j]
        if name.startswith(("sc_", "ac_")):  # the girdle's: the hand is below them too, but checked as GH is
            continue
        dM = -(np.cross(r - fr.p[0, s], F) + M)  # about the coordinate's joint centre
        want = fr.axes[0, j] @ dM
        col = f"{name}_generalized_force_Nm"
        assert loaded.column(col)[0] - base.column(col)[0] == pytest.approx(want, abs=1e-10), name


def test_the_same_load_in_lab_thorax_or_segment_frame(model):
    from scipy.spatial.transform import Rotation

    from exubio.dynamics.thorax_motion import ThoraxMotion

    q, qd, qdd = _static(model)
    n = q.shape[0]
    R = Rotation.from_euler("xyz", [10, -30, 50], degrees=True).as_matrix()
    z = np.zeros((n, 3))
    thorax = ThoraxMotion(np.arange(n) * 0.01, np.tile(R, (n, 1, 1)), z, z, z, z, z, R @ np.array([0, -9.80665, 0.0]))
    F_t, M_t = np.array([3.0, 4.0, -12.0]), np.array([0.5, 0.0, -0.2])
    hand = model.segment_index("hand")
    R_hand = Kinematics(model).frames(q).R[0, hand]
    out = []
    for frame, f, m in (("thorax", F_t, M_t), ("lab", R @ F_t, R @ M_t), ("segment", R_hand.T @ F_t, R_hand.T @ M_t)):
        load = ExternalLoad("hand", frame, np.tile(f, (n, 1)), np.tile(m, (n, 1)), np.zeros((n, 3)), frame)
        out.append(joint_moments(model, q, qd, qdd, thorax=thorax, loads=[load]).values)
    np.testing.assert_allclose(out[1], out[0], atol=1e-10)
    np.testing.assert_allclose(out[2], out[0], atol=1e-10)


def _write(path, rows, header=LOAD_COLUMNS):
    lines = [",".join(header)] + [",".join(str(x) for x in r) for r in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _rows(t0=-0.1, t1=0.7, rate=1000.0, segment="hand", frame="thorax", fy=-19.6):
    t = np.arange(int(round((t1 - t0) * rate)) + 1) / rate + t0
    return [[f"{x:.6f}", 0, fy, 0, 0, 0, 0, 0, -0.08, 0, segment, frame] for x in t]


def test_resampled_constant_load_is_itself(model, tmp_path):
    raw = read_loads_csv(_write(tmp_path / "l.csv", _rows()), segments=model.segment_names[1:])
    load = resample_load(raw, np.arange(50) * 0.01, cutoff_hz=6.0)
    np.testing.assert_allclose(load.force_N, np.tile([0.0, -19.6, 0.0], (50, 1)), atol=1e-9)
    np.testing.assert_allclose(load.point_m, np.tile([0.0, -0.08, 0.0], (50, 1)), atol=1e-12)


@pytest.fixture(scope="module")
def trial_c3d(tmp_path_factory):
    out = tmp_path_factory.mktemp("loads") / "short.c3d"
    assert main(["simulate", "--motion", "abduction", "--duration", "0.5", "--out", str(out)]) == 0
    return out


def test_reconstruct_with_a_load_file(tmp_path, trial_c3d):
    """A load file on a simulated trial: read, filtered, resampled, named in the moments file."""
    good = _write(tmp_path / "weight.csv", _rows())
    out = tmp_path / "out"
    assert main(["reconstruct", str(trial_c3d), "--method", "ls", "--body-mass", str(MASS), "--loads", str(good),
                 "--out", str(out), "--no-report", "-q"]) == 0
    text = (out / "short.ls.moments.csv").read_text(encoding="utf-8")
    assert "weight.csv" in text and "external load" in text and "thorax motion in the lab included" in text
    assert (out / "short.ls.thorax.csv").is_file()
    t, cols, values = read_moments_csv(out / "short.ls.moments.csv")
    assert np.isfinite(values).all()


@pytest.mark.parametrize("case, column", [
    ("missing", "fz_N"), ("text", "fy_N"), ("short", "time_s"), ("segment", "segment"), ("frame", "frame"),
    ("mixed", "frame"), ("backwards", "time_s")])
def test_a_bad_load_file_is_one_clear_error(tmp_path, trial_c3d, capsys, case, column):
    rows = _rows()
    header = LOAD_COLUMNS
    if case == "missing":
        header = tuple(c for c in LOAD_COLUMNS if c != "fz_N")
        rows = [r[:3] + r[4:] for r in rows]
    elif case == "text":
        rows[5][2] = "heavy"
    elif case == "short":
        rows = _rows(t0=0.0, t1=0.3)
    elif case == "segment":
        rows = _rows(segment="glove")
    elif case == "frame":
        rows = _rows(frame="world")
    elif case == "mixed":
        rows[3][11] = "lab"
    elif case == "backwards":
        rows[4][0], rows[5][0] = rows[5][0], rows[4][0]
    bad = _write(tmp_path / f"{case}.csv", rows, header)
    code = main(["reconstruct", str(trial_c3d), "--method", "ls", "--body-mass", str(MASS), "--loads", str(bad),
                 "--out", str(tmp_path / "out"), "--no-report", "-q"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert str(bad) in err and f"'{column}'" in err, err
    assert "Traceback" not in err
    assert not (tmp_path / "out" / "short.ls.csv").exists()


def _with_analogs(src, dst, n_frames, labels=("Fx", "Fy", "Fz", "Mx", "My", "Mz")):
    ezc3d = pytest.importorskip("ezc3d")
    c = ezc3d.c3d(str(src))
    c["parameters"]["ANALOG"]["RATE"]["value"] = np.array([1000.0])
    c["parameters"]["ANALOG"]["LABELS"]["value"] = list(labels)
    c["parameters"]["ANALOG"]["UNITS"]["value"] = ["N", "N", "N", "Nmm", "Nmm", "Nmm"]
    a = np.zeros((1, 6, n_frames * 10))
    a[0, 1], a[0, 5] = -19.5, 500.0  # exact in the file's 32-bit floats
    c["data"]["analogs"] = a
    c.write(str(dst))
    return dst


def test_a_protocol_maps_a_c3ds_analog_channels_to_a_load(tmp_path, trial_c3d, capsys):
    """The same load from the C3D's analog channels (N, N mm) and from a CSV gives the same moments."""
    c3d = _with_analogs(trial_c3d, tmp_path / "an.c3d", 50)
    proto = tmp_path / "analog.yaml"
    proto.write_text("schema_version: 1\nextends: upper_limb_21\nanalog_loads:\n  - force: [Fx, Fy, Fz]\n"
                     "    moment: [Mx, My, Mz]\n    segment: hand\n    point_mm: [0, -80, 0]\n    frame: thorax\n",
                     encoding="utf-8")
    csv = _write(tmp_path / "same.csv", [[f"{k / 1000:.3f}", 0, -19.5, 0, 0, 0, 0.5, 0, -0.08, 0, "hand", "thorax"]
                                        for k in range(501)])
    common = ["--method", "ls", "--body-mass", str(MASS), "--no-report", "-q"]
    assert main(["reconstruct", str(c3d), "--protocol", str(proto), "--out", str(tmp_path / "a"), *common]) == 0
    assert main(["reconstruct", str(c3d), "--loads", str(csv), "--out", str(tmp_path / "b"), *common]) == 0
    assert main(["reconstruct", str(c3d), "--out", str(tmp_path / "c"), *common]) == 0
    _, cols, a = read_moments_csv(tmp_path / "a" / "an.ls.moments.csv")
    _, _, b = read_moments_csv(tmp_path / "b" / "an.ls.moments.csv")
    _, _, c = read_moments_csv(tmp_path / "c" / "an.ls.moments.csv")
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    assert np.abs(a - c).max() > 1.0  # the load is in
    assert "analog channels" in (tmp_path / "a" / "an.ls.moments.csv").read_text(encoding="utf-8")
    # a channel the file lacks: exit 2 naming it
    bad = _with_analogs(trial_c3d, tmp_path / "bad.c3d", 50, labels=("Fx", "Fy", "Fz_", "Mx", "My", "Mz"))
    capsys.readouterr()
    assert main(["reconstruct", str(bad), "--protocol", str(proto), "--out", str(tmp_path / "d"), *common]) == 2
    err = capsys.readouterr().err
    assert "analog channel 'Fz'" in err and "bad.c3d" in err and "Traceback" not in err, err
