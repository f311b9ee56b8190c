"""models/sources/biomod_markers.py: the pure-python bioMod reader (hand-written files with
hand-computed answers) and the lab's model of ../shared/data/models (Ipuch/bioptim_exo, MIT; see
../shared/data/SOURCES.md), skipped when that folder is absent."""
from __future__ import annotations

import importlib.util
import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(__file__).resolve().parents[3] / "shared"
BIOMOD = SHARED / "data" / "models" / "bioptim_exo_wu_converted_definitif.bioMod"

_spec = importlib.util.spec_from_file_location("biomod_markers", ROOT / "models" / "sources" / "biomod_markers.py")
bm = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("biomod_markers", bm)   # dataclasses look their module up there
_spec.loader.exec_module(bm)

# Two segments. base: RT angles (pi/2, 0, pi/2) sequence xyz, translation (1, 2, 3).
# biorbd composes the angles intrinsically: R = Rx(90) @ Rz(90) = [[0,-1,0],[0,0,-1],[1,0,0]]
# (the extrinsic reading Rz(90) @ Rx(90) = [[0,0,1],[1,0,0],[0,1,0]] would give other answers).
# arm: 4x4 RT, identity rotation, translation (0, 0, $len = 0.5), DoF translation y then rotation z.
# Marker TIP at (1, 0, 0) on arm.
TINY = """version 4
// a line comment: segment ghost parent ground endsegment
variables
    $len 0.5
endvariables
segment base
    parent ground
    RTinMatrix 0
    RT pi/2 0 pi/2 xyz 1 2 3
    mass 1
    com 0 0 0
    meshfile geometry/none.vtp
endsegment
segment arm
    parent base
    RTinMatrix 1
    RT
        1 0 0 0
        0 1 0 0
        0 0 1 $len
        0 0 0 1
    translations y
    rotations z
    ranges -1 1
           -pi pi
    mass 2
endsegment
segment fixed_tip
    parent arm
    RT 0 0 0 xyz 0 0 0
    ranges -1 1
endsegment
marker TIP
    parent arm
    position 1 0 0
endmarker
/*
marker HIDDEN
    parent base
    position 0 0 1
endmarker
*/
musclegroup g
    OriginParent base
    InsertionParent arm
endmusclegroup
"""


def test_tiny_biomod_structure():
    model = bm.parse_biomod(TINY)
    assert list(model.segments) == ["base", "arm", "fixed_tip"]
    assert model.segments["base"].parent is None                 # "ground" is the world
    assert model.nq == 2
    assert model.dof_names == ["arm:TransY", "arm:RotZ"]
    assert model.true_segments == ["base", "arm"]
    assert list(model.markers) == ["TIP"]                        # HIDDEN is commented out
    hidden = bm.commented_out_markers(TINY, model)
    assert list(hidden) == ["HIDDEN"] and hidden["HIDDEN"].parent == "base"
    np.testing.assert_allclose(model.segments["base"].rt[:3, :3],
                               [[0, -1, 0], [0, 0, -1], [1, 0, 0]], atol=1e-12)


@pytest.mark.parametrize(
    "q, expected",
    [
        # q = 0: base maps (1, 0, 0.5) to col0 + 0.5 col2 = (0, 0, 1) + (0, -0.5, 0); + (1, 2, 3)
        ((0.0, 0.0), (1.0, 1.5, 4.0)),
        # Rz(90) turns (1, 0, 0) into (0, 1, 0): arm point (0, 1, 0.5) -> col1 + 0.5 col2
        # = (-1, 0, 0) + (0, -0.5, 0); + (1, 2, 3)
        ((0.0, math.pi / 2), (0.0, 1.5, 3.0)),
        # translation 0.2 along the arm's y first: (0, 1.2, 0.5) -> (-1.2, -0.5, 0) + (1, 2, 3)
        ((0.2, math.pi / 2), (-0.2, 1.5, 3.0)),
        # q_t only: (0, 0.2, 0) + (1, 0, 0.5) -> (1, 0.2, 0.5) -> (-0.2, -0.5, 1) + (1, 2, 3)
        ((0.2, 0.0), (0.8, 1.5, 4.0)),
    ],
)
def test_tiny_biomod_marker_position(q, expected):
    model = bm.parse_biomod(TINY)
    np.testing.assert_allclose(bm.marker_positions(model, np.array(q))["TIP"], expected, atol=1e-12)


def test_rotation_from_angles_is_intrinsic():
    a = (0.3, -0.7, 1.1)
    rx, ry, rz = (bm.elementary_rotation(c, x) for c, x in zip("xyz", a))
    np.testing.assert_allclose(bm.rotation_from_angles(a, "xyz"), rx @ ry @ rz, atol=1e-12)
    assert not np.allclose(bm.rotation_from_angles(a, "xyz"), rz @ ry @ rx, atol=1e-3)


def test_rt_that_is_not_a_rotation_is_refused():
    bad = TINY.replace("        1 0 0 0\n        0 1 0 0", "        2 0 0 0\n        0 1 0 0")
    with pytest.raises(ValueError, match="unitary"):
        bm.parse_biomod(bad)


def test_wrong_number_of_q_is_refused():
    with pytest.raises(ValueError, match="coordinates"):
        bm.global_frames(bm.parse_biomod(TINY), np.zeros(3))


def test_isb_thorax_frame_follows_a_rigid_motion():
    # landmarks in a frame already X anterior, Y superior, Z right, origin IJ
    ij, c7 = np.array([0.0, 0, 0]), np.array([-0.13, 0.05, 0.0])
    px, t8 = np.array([0.04, -0.17, 0.0]), np.array([-0.16, -0.13, 0.0])
    y = (ij + c7) / 2 - (px + t8) / 2
    y /= np.linalg.norm(y)
    ref = bm.isb_thorax_frame(ij, c7, px, t8)
    np.testing.assert_allclose(ref[:3, 2], [0, 0, 1], atol=1e-12)      # normal to the plane, right
    np.testing.assert_allclose(ref[:3, 1], y, atol=1e-12)
    assert ref[0, 0] > 0.99                                             # X anterior
    rot = bm.rotation_from_angles((0.4, -1.2, 2.0), "zyx")
    shift = np.array([0.3, -0.5, 1.2])
    moved = bm.isb_thorax_frame(*(rot @ p + shift for p in (ij, c7, px, t8)))
    np.testing.assert_allclose(moved[:3, :3], rot @ ref[:3, :3], atol=1e-12)
    np.testing.assert_allclose(moved[:3, 3], shift, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(moved[:3, :3]), 1.0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# The lab's model (../shared/data/models)
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lab_model():
    if not BIOMOD.is_file():
        pytest.skip(f"shared model {BIOMOD} not available")
    return bm.load_biomod(BIOMOD)


IN_MODEL = ("MAN", "XYP", "C7", "T10", "CLAV_SC", "CLAV_AC", "SCAP_AC", "SCAP_IA", "SCAP_BACK",
            "SCAP_FRONT", "ARM", "DELT", "EPI_lat", "EPI_med", "ELB", "ULNA", "RADIUS", "MET2", "MET5",
            "SEML")


def test_lab_model_markers(lab_model):
    assert sorted(lab_model.markers) == sorted(IN_MODEL)
    # the two others of the 22-name marker set are written in /* */ blocks of the file only
    hidden = bm.commented_out_markers(BIOMOD, lab_model)
    assert set(hidden) == {"SCAP_Cor", "SCAP_AA"}
    assert set(IN_MODEL) | set(hidden) == set(bm.MARKER_SET)
    assert lab_model.true_segments == ["thorax", "clavicle", "scapula", "humerus", "ulna", "radius", "hand_r"]
    assert lab_model.nq == 16


def test_lab_model_rigid_distances_do_not_depend_on_q(lab_model):
    rng = np.random.default_rng(7)
    groups = bm.rigid_groups(lab_model)
    assert ["radius", "hand_r"] in groups                       # no wrist DoF in this model
    members = {tuple(g): [n for n, m in lab_model.markers.items() if m.parent in g] for g in groups}
    ref = bm.marker_positions(lab_model)
    moved_any = False
    for _ in range(5):
        q = rng.uniform(-1.5, 1.5, lab_model.nq)
        pos = bm.marker_positions(lab_model, q)
        for names in members.values():
            for a, b in itertools.combinations(names, 2):
                # 1e-8 m: the file's 4x4 rotations are orthonormal to about 1e-9 only
                assert np.linalg.norm(pos[a] - pos[b]) == pytest.approx(np.linalg.norm(ref[a] - ref[b]), abs=1e-8)
        # across a joint the distance does change (the check above can fail)
        moved_any |= abs(np.linalg.norm(pos["EPI_lat"] - pos["MAN"]) - np.linalg.norm(ref["EPI_lat"] - ref["MAN"])) > 1e-3
    assert moved_any


def test_lab_model_frames_are_parallel_at_q0(lab_model):
    # the "reset_axis" segments of the converted OpenSim model cancel the joint-axis bases: every
    # true segment's frame is parallel to the thorax's at q = 0 (a wrong angle convention breaks it:
    # the scapula offset and RT, given as xyz angles, cancel only when composed intrinsically)
    frames = bm.global_frames(lab_model)
    for seg in lab_model.true_segments:
        assert bm.rotation_angle_deg(frames["thorax"][:3, :3].T @ frames[seg][:3, :3]) < 0.05, seg
