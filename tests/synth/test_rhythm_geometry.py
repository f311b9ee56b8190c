"""The generic model's published girdle geometry carries Ludewig et al.'s (2009) mean rhythm:
``exubio simulate`` in the coronal, scapular and sagittal planes reproduces Ludewig's SC and ST
angle changes over HT 30-120 deg within 3 deg, with the scapula on the thorax ellipsoid
(|g| < 1e-9). The references are Ludewig's published numbers (exubio/data/ludewig2009.csv), the
angles are measured on the simulated truth with exubio.model.angles (ISB frames from the landmarks)."""
import numpy as np
import pytest

from exubio.model.angles import humerothoracic_elevation, isb_angles
from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.literature.reference import load_ludewig2009
from exubio.io.resources import shipped_file
from exubio.synth.rhythm import PLANE_OF
from exubio.synth.simulate import Motion, simulate_trial

# Ludewig column (axis suffix dropped) -> (exubio ISB angle set, index)
COLUMNS = {"SC_protraction": ("SC", 0), "SC_elevation": ("SC", 1), "SC_rotation": ("SC", 2),
           "ST_protraction": ("ST", 0), "ST_medRotation": ("ST", 1), "ST_tilt": ("ST", 2)}


@pytest.fixture(scope="module")
def model():
    return load_model(shipped_file("exubio.models", "upper_extremity.yaml", "models"))


@pytest.mark.parametrize("motion", [Motion.ABDUCTION, Motion.SCAPTION, Motion.FLEXION])
def test_simulated_rhythm_matches_ludewig_in_three_planes(model, motion):
    trial = simulate_trial(model, motion, duration_s=2.5, rate_hz=200.0, noise_mm=0.0, sta_mm=0.0)
    q = trial.q_true
    kin = Kinematics(model)
    assert np.abs(kin.g(q)).max() < 1e-9
    ht = np.degrees(humerothoracic_elevation(model, q, kinematics=kin))
    ang = {k: np.degrees(v) for k, v in isb_angles(model, q, kinematics=kin).items()}
    lud = load_ludewig2009()[PLANE_OF[motion.value]]
    lud_ht = lud["ht_elevation_deg"]
    rising = np.arange(int(np.argmax(ht)) + 1)  # 10 -> 120 deg, monotonic
    sel = rising[(ht[rising] >= 30.0) & (ht[rising] <= 120.0)]
    i30 = rising[int(np.argmin(np.abs(ht[rising] - 30.0)))]
    assert abs(ht[i30] - 30.0) < 0.5 and ht[sel].max() > 119.0
    worst = {}
    for col, (joint, k) in COLUMNS.items():
        name = next(n for n in lud if n.rsplit("_", 1)[0] == col)
        ref = np.interp(ht[sel], lud_ht, lud[name]) - np.interp(ht[i30], lud_ht, lud[name])
        got = ang[joint][sel, k] - ang[joint][i30, k]
        worst[col] = float(np.abs(got - ref).max())
    assert max(worst.values()) < 3.0, worst


def test_reference_posture_lies_on_the_ellipsoid(model):
    """The model file's ellipsoid (six decimals, mm) passes through TS and AI of the zero posture."""
    kin = Kinematics(model)
    assert np.abs(kin.g(np.zeros(model.n_coordinates))).max() < 1e-7
