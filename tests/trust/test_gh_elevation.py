"""The glenohumeral bound on GH elevation (exubio.trust.quality.GH_ELEVATION_MAX_DEG), which replaces
the ranges of gh_abduction and gh_flexion (models/upper_extremity.yaml, note [13]): postures near the
solver sequence's gimbal lock pass, a humerus no shoulder can hold is named."""
import numpy as np
import pytest

from exubio.model.anatomy import isb_frame
from exubio.model.angles import anatomical_table
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.trust.assess import gh_elevation_limit
from exubio.trust.quality import GH_ELEVATION_MAX_DEG, limit_reasons


@pytest.fixture(scope="module")
def model():
    return load_model()


def _posture(model, **deg):
    q = np.zeros(model.n_coordinates)
    for name, value in deg.items():
        q[model.coordinate_names.index(name)] = np.radians(value)
    return q


def _elevation_between_long_axes_deg(model, q):
    """GH elevation from the landmarks themselves: the angle between the ISB Y axes of the scapula
    and the humerus built from AA, TS, AI and GH, EL, EM where the posture puts them."""
    kin = Kinematics(model)
    names = {"scapula": ("AA", "TS", "AI"), "humerus": ("GH", "EL", "EM")}
    frames = {}
    for seg, pts in names.items():
        at = kin.points(q[None], kin.point_set([(seg, model.segment(seg).points[p]) for p in pts]))[0]
        frames[seg] = isb_frame(seg, dict(zip(pts, at)))
    return float(np.degrees(np.arccos(np.clip(frames["scapula"][:, 1] @ frames["humerus"][:, 1], -1.0, 1.0))))


def test_the_bound_is_on_the_angle_between_the_long_axes(model):
    qs = [_posture(model), _posture(model, gh_abduction=175.0), _posture(model, gh_flexion=120.0, gh_abduction=30.0)]
    names, table = anatomical_table(model, np.array(qs))
    got = np.degrees(np.abs(table[:, names.index("GH_X_elevation")]))
    want = [_elevation_between_long_axes_deg(model, q) for q in qs]
    assert got == pytest.approx(want, abs=1e-6)


def test_postures_near_the_sequence_lock_pass_and_an_impossible_humerus_fails(model):
    # the bone pins' abduction (ARTANIM armAbd): far outside the old coordinate ranges, GH elevation well inside
    near_lock = _posture(model, gh_abduction=-117.0, gh_internal_rotation=77.0, gh_flexion=-83.0)
    palm_down_t_pose = _posture(model, gh_abduction=90.0, gh_internal_rotation=95.0, gh_flexion=-10.0)
    assert max(_elevation_between_long_axes_deg(model, q) for q in (near_lock, palm_down_t_pose)) < 120.0
    assert gh_elevation_limit(*anatomical_table(model, np.array([near_lock, palm_down_t_pose]))) == []

    over = _posture(model, gh_abduction=178.0)  # the arm turned up past the head, then further
    elevation = _elevation_between_long_axes_deg(model, over)
    assert elevation > GH_ELEVATION_MAX_DEG + 5.0
    q = np.array([_posture(model)] * 3 + [over] * 2)
    (report,) = gh_elevation_limit(*anatomical_table(model, q))
    assert report.coordinate == "GH_X_elevation" and report.frames_at_limit == 2 and report.first_frame == 3
    assert report.max_beyond_deg == pytest.approx(elevation - GH_ELEVATION_MAX_DEG, abs=1e-6)
    (reason,) = limit_reasons([vars(report)], 5)
    assert reason.level == "fail" and "GH_X_elevation at its range limit [-150, 150] deg in 2 of 5 frames" in reason.message


def test_reaching_the_bound_is_a_check(model):
    e0 = _elevation_between_long_axes_deg(model, _posture(model))
    lo, hi = 140.0, 179.0  # gh_abduction giving GH elevation 2 deg past the bound, found by bisection
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _elevation_between_long_axes_deg(model, _posture(model, gh_abduction=mid)) < GH_ELEVATION_MAX_DEG + 2.0 else (lo, mid)
    (report,) = gh_elevation_limit(*anatomical_table(model, _posture(model, gh_abduction=hi)[None]))
    assert report.max_beyond_deg == pytest.approx(2.0, abs=1e-6) and e0 < 20.0
    (reason,) = limit_reasons([vars(report)], 1)
    assert reason.level == "check"
