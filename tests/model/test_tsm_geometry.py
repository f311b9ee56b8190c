"""models/sources/tsm_geometry.py: a pure-python forward-kinematics reader of the thoracoscapular
OpenSim model (Seth et al. 2019, Front Neurorobot 13:90, CC BY 4.0; file and TRC data from
../shared/data, see ../shared/data/SOURCES.md). Tests that need ../shared/data skip when absent."""
from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
OSIM = DATA / "models" / "rmr_TSM_subject_noWeight.osim"
TRC = DATA / "trc" / "tsm_rmr_ABD01.trc"

_spec = importlib.util.spec_from_file_location("tsm_geometry", REPO / "models" / "sources" / "tsm_geometry.py")
tg = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("tsm_geometry", tg)      # dataclasses look their module up there
_spec.loader.exec_module(tg)

needs_osim = pytest.mark.skipif(not OSIM.is_file(), reason=f"model file {OSIM} is absent")
needs_trc = pytest.mark.skipif(not (OSIM.is_file() and TRC.is_file()), reason=f"{OSIM} or {TRC} is absent")


@pytest.fixture(scope="module")
def tsm():
    if not OSIM.is_file():
        pytest.skip(f"model file {OSIM} is absent")
    return tg.load_tsm(OSIM)


def read_trc_first_frame(path: Path) -> dict[str, np.ndarray]:
    """Minimal independent TRC reader (tab separated, labels on line 4, data from line 6), mm."""
    lines = path.read_text(encoding="utf-8").splitlines()
    labels = [t.strip() for t in lines[3].split("\t")[2:] if t.strip()]
    row = next(l for l in lines[5:] if l.strip())
    vals = np.array([float(c) for c in row.split("\t")[2:2 + 3 * len(labels)]])
    return {n: vals[3 * i:3 * i + 3] for i, n in enumerate(labels)}


def kabsch_rms(src: np.ndarray, dst: np.ndarray) -> float:
    cs, cd = src.mean(0), dst.mean(0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    res = (src - cs) @ R.T + cd - dst
    return float(np.sqrt((res ** 2).sum(1).mean()))


def random_coords(tsm, rng, names, lo=-0.6, hi=0.6):
    q = tsm.default_coords()
    q.update({n: float(rng.uniform(lo, hi)) for n in names})
    return q


# ------------------------------------------------------------------ pure functions (no data needed)
def test_isb_thorax_frame_axes_on_a_synthetic_thorax():
    # A thorax in a frame with x anterior, y up, z right, then rotated and shifted arbitrarily.
    ij, c7 = np.array([0.0, 0, 0]), np.array([-0.10, 0.05, 0])
    px, t8 = np.array([0.05, -0.17, 0]), np.array([-0.14, -0.14, 0])
    R0 = tg.body_xyz((0.3, -1.1, 0.7))
    p0 = np.array([0.4, 1.2, -0.3])
    X = tg.isb_thorax_frame(*(R0 @ v + p0 for v in (ij, c7, px, t8)))
    np.testing.assert_allclose(X.p, p0, atol=1e-12)
    np.testing.assert_allclose(X.R.T @ X.R, np.eye(3), atol=1e-12)
    assert np.linalg.det(X.R) == pytest.approx(1.0)
    R_local = R0.T @ X.R                       # the ISB axes seen in the synthetic frame
    y_exp = (ij + c7) / 2 - (px + t8) / 2
    np.testing.assert_allclose(R_local[:, 1], y_exp / np.linalg.norm(y_exp), atol=1e-12)
    np.testing.assert_allclose(R_local[:, 2], [0, 0, 1], atol=1e-12)   # right
    assert R_local[0, 0] > 0.9                                          # anterior


def test_custom_joint_rotations_are_body_fixed_about_normalised_axes():
    a0, a1 = np.array([0.0153, 0.9893, -0.1451]), np.array([-0.9945, 0.0, -0.1050])
    joint = tg.Joint("j", "CustomJoint", None, None, [tg.Coordinate("u", 0, (0, 0)), tg.Coordinate("v", 0, (0, 0))])
    funcs = [(["u"], a0), (["v"], 3 * a1), ([], np.array([0, 1.0, 0]))]
    for cn, ax in funcs:
        joint.axes.append(tg.TransformAxisDef("r", cn, ax, (lambda x: x[0]) if cn else (lambda x: 0.0), ""))
    for k, ax in enumerate(np.eye(3)):
        joint.axes.append(tg.TransformAxisDef("t", [], ax, lambda x, k=k: 0.01 * (k + 1), ""))
    X = tg.custom_joint_X_FM(joint, {"u": 0.7, "v": -0.4})
    # independent: rotate the frame about a0 by 0.7, then about the rotated a1 by -0.4
    R1 = tg.rot_axis(a0, 0.7)
    a1_rotated = R1 @ (a1 / np.linalg.norm(a1))
    np.testing.assert_allclose(X.R, tg.rot_axis(a1_rotated, -0.4) @ R1, atol=1e-12)
    np.testing.assert_allclose(X.p, [0.01, 0.02, 0.03], atol=1e-15)


# ------------------------------------------------------------------ the model file
@needs_osim
def test_file_structure(tsm):
    kinds = {j.name: j.kind for j in tsm.joints}
    assert kinds == {"ground_thorax": "CustomJoint", "sternoclavicular": "CustomJoint",
                     "scapulothoracic": "ScapulothoracicJoint", "GlenoHumeral": "CustomJoint",
                     "elbow": "CustomJoint", "radioulnar": "CustomJoint", "rc": "WeldJoint"}
    assert len(tsm.coordinates) == 17
    st = tsm.scapulothoracic()
    assert [c.name for c in st.coordinates] == ["scapula_abduction", "scapula_elevation",
                                                "scapula_upward_rot", "scapula_winging"]
    assert st.ellipsoid_radii[1] > 2 * st.ellipsoid_radii[0]          # tall ellipsoid (Y radius)
    for name in ("ij", "c7", "t8", "px", "sc", "ac", "aa", "ts", "ai", "gu", "EpL", "EpM", "centelbow"):
        assert name in tsm.markers


@needs_osim
def test_markers_sit_at_their_file_locations_on_their_bodies(tsm):
    rng = np.random.default_rng(3)
    q = random_coords(tsm, rng, list(tsm.coordinates))
    X = tg.body_transforms(tsm, q)
    pts = tg.marker_positions(tsm, q)
    for m in tsm.markers.values():
        np.testing.assert_allclose(X[m.body].inv().apply(pts[m.name]), m.location, atol=1e-12)


@needs_osim
def test_scapulothoracic_contact_point_stays_on_the_ellipsoid(tsm):
    st = tsm.scapulothoracic()
    rx, ry, rz = st.ellipsoid_radii
    rng = np.random.default_rng(7)
    names = [c.name for c in st.coordinates] + ["ground_thorax_rot_x", "ground_thorax_rot_z", "clav_prot"]
    moved = []
    for _ in range(25):
        q = random_coords(tsm, rng, names, -1.0, 1.0)
        X = tg.body_transforms(tsm, q)
        F = X["thorax"] @ st.parent.X                     # ellipsoid frame (parent offset frame)
        p = F.inv().apply(X["scapula"].apply(st.child.translation))   # child frame origin in F
        assert abs((p[0] / rx) ** 2 + (p[1] / ry) ** 2 + (p[2] / rz) ** 2 - 1.0) < 1e-9
        moved.append(p)
    assert np.ptp(np.array(moved), axis=0).min() > 0.02    # it really moves over the surface


@needs_osim
def test_scapulothoracic_reference_configuration_and_upward_rotation_axis(tsm):
    st = tsm.scapulothoracic()
    names = [c.name for c in st.coordinates]
    q = {**tsm.default_coords(), **{n: 0.0 for n in names}}
    X = tg.body_transforms(tsm, q)
    F = X["thorax"] @ st.parent.X
    M = X["scapula"] @ st.child.X
    rel = F.inv() @ M
    # at q = 0 the child frame is parallel to the parent frame, at (0, 0, rz) on the ellipsoid
    np.testing.assert_allclose(rel.R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(rel.p, [0, 0, st.ellipsoid_radii[2]], atol=1e-12)
    # upward rotation alone spins the scapula about the child frame's Z axis (through its origin)
    q2 = dict(q, scapula_upward_rot=0.5)
    X2 = tg.body_transforms(tsm, q2)
    rel2 = F.inv() @ (X2["scapula"] @ st.child.X)
    np.testing.assert_allclose(rel2.p, rel.p, atol=1e-12)
    np.testing.assert_allclose(rel2.R, tg.rot_z(0.5), atol=1e-12)


@needs_osim
def test_glenohumeral_rotation_keeps_distances_from_its_centre(tsm):
    rng = np.random.default_rng(11)
    gh_names = ["plane_elv", "shoulder_elv", "axial_rot"]
    base = tg.marker_positions(tsm)
    for _ in range(10):
        q = random_coords(tsm, rng, gh_names, -1.2, 1.2)
        pts = tg.marker_positions(tsm, q)
        np.testing.assert_allclose(pts["GH_centre"], base["GH_centre"], atol=1e-12)
        for n in ("EpL", "EpM", "centelbow", "gu", "elbow_centre"):
            assert np.linalg.norm(pts[n] - pts["GH_centre"]) == pytest.approx(
                np.linalg.norm(base[n] - base["GH_centre"]), abs=1e-12)
        for n in ("ac", "aa", "ts", "ai"):              # the girdle does not move
            np.testing.assert_allclose(pts[n], base[n], atol=1e-12)
        assert np.linalg.norm(pts["EpL"] - base["EpL"]) > 1e-3


@needs_osim
def test_sternoclavicular_joint_pivots_about_sc(tsm):
    rng = np.random.default_rng(5)
    base = tg.marker_positions(tsm)
    L = np.linalg.norm(base["acc"] - base["sc"])
    for _ in range(10):
        q = random_coords(tsm, rng, ["clav_prot", "clav_elev"], -0.8, 0.8)
        pts = tg.marker_positions(tsm, q)
        np.testing.assert_allclose(pts["sc"], base["sc"], atol=1e-12)
        assert np.linalg.norm(pts["acc"] - pts["sc"]) == pytest.approx(L, abs=1e-12)


@needs_osim
def test_file_defaults_violate_the_ac_constraint_and_assembly_fixes_it(tsm):
    gap0 = np.linalg.norm(tg.constraint_violation(tsm))
    assert 0.010 < gap0 < 0.030                          # the file's defaults: about 19 mm
    q = tg.assemble(tsm)
    assert np.linalg.norm(tg.constraint_violation(tsm, q)) < 1e-9
    d = tsm.default_coords()
    changed = {k for k in d if abs(q[k] - d[k]) > 1e-9}
    assert changed <= {"clav_prot", "clav_elev", "scapula_abduction", "scapula_elevation",
                       "scapula_upward_rot", "scapula_winging"}
    # closest point: q - defaults is orthogonal to every constraint-preserving direction
    girdle = sorted(changed)
    x = np.array([q[k] for k in girdle])

    def c_of(v):
        return tg.constraint_violation(tsm, {**q, **dict(zip(girdle, v))})

    J = np.column_stack([(c_of(x + 1e-7 * e) - c_of(x - 1e-7 * e)) / 2e-7 for e in np.eye(len(x))])
    null = np.linalg.svd(J)[2][3:]                    # 3 directions that keep the AC gap at zero
    delta = x - np.array([d[k] for k in girdle])
    assert np.linalg.norm(delta) > 0.05
    assert np.abs(null @ delta).max() < 1e-6 * np.linalg.norm(delta) + 1e-9


@needs_osim
def test_isb_thorax_frame_of_the_model(tsm):
    pts = tg.marker_positions(tsm)
    X = tg.thorax_frame_of(pts)
    loc = {n: X.inv().apply(pts[n]) for n in ("ij", "c7", "px", "t8", "ac", "GH_centre")}
    np.testing.assert_allclose(loc["ij"], 0, atol=1e-12)
    assert abs(loc["c7"][2]) < 1e-12 and loc["c7"][0] < -0.05           # C7 posterior, in the plane
    assert abs((loc["px"][2] + loc["t8"][2]) / 2) < 1e-12
    assert loc["ac"][2] > 0.1 and loc["GH_centre"][2] > 0.1             # right arm on +Z
    # OpenSim's thorax frame is also X anterior, Y up, Z right: the two frames nearly agree
    R_rel = X.R.T @ tg.body_transforms(tsm)["thorax"].R
    assert np.degrees(np.arccos((np.trace(R_rel) - 1) / 2)) < 15


# ------------------------------------------------------------------ against the TRC data
@needs_trc
def test_model_thorax_markers_fit_the_trc_first_frame(tsm):
    trc = read_trc_first_frame(TRC)
    pts = tg.marker_positions(tsm)
    names = ("ij", "centijc7", "centpxt8")
    src = np.array([1000 * pts[n] for n in names])
    dst = np.array([trc[n] for n in names])
    assert kabsch_rms(src, dst) < 5.0
    T, rms, _ = tg.thorax_fit_to_trc(tsm, TRC)
    assert rms == pytest.approx(kabsch_rms(src, dst), abs=1e-9)


@needs_trc
def test_humerus_marker_distances_match_the_trc(tsm):
    trc = read_trc_first_frame(TRC)
    pts = tg.marker_positions(tsm)
    for a, b in (("gu", "EpL"), ("gu", "centelbow"), ("EpL", "centelbow")):
        model = 1000 * np.linalg.norm(pts[a] - pts[b])
        data = np.linalg.norm(trc[a] - trc[b])
        assert model == pytest.approx(data, abs=15.0), (a, b)


@needs_trc
def test_inverse_kinematics_of_the_trc_first_frame(tsm):
    # OpenSim 4.6 IK with this model fits these trials with 8-9 mm marker RMS (SOURCES.md).
    trc = read_trc_first_frame(TRC)
    T, _, _ = tg.thorax_fit_to_trc(tsm, TRC)
    targets = {n: T.inv().apply(v) / 1000 for n, v in trc.items()}
    q, rms = tg.fit_markers(tsm, targets)
    assert rms < 0.012
    assert np.linalg.norm(tg.constraint_violation(tsm, q)) < 1e-4
    assert math.degrees(q["shoulder_elv"]) < 45                     # the trial starts arm down


@needs_osim
def test_written_json_matches_the_current_computation(tsm):
    path = REPO / "models" / "sources" / "tsm_landmarks.json"
    if not path.is_file():
        pytest.skip("tsm_landmarks.json not generated")
    stored = json.loads(path.read_text(encoding="utf-8"))
    assert "Seth" in stored["source"]["citation"]
    X = tg.thorax_frame_of(tg.marker_positions(tsm))
    pts = tg.marker_positions(tsm, tg.assemble(tsm))
    for n in ("GH_centre", "aa", "ts", "ai", "coracoid_est"):
        np.testing.assert_allclose(stored["landmarks_mm"]["default_assembled"][n],
                                   1000 * X.inv().apply(pts[n]), atol=0.01)
