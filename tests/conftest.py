"""Fixtures shared by the test modules (the generic model and its kinematics), and the markers that
show the layers: ``exudyn`` (the test runs the PF engine) and ``slow`` (an end-to-end run: the CLI,
a study, the real trials, a browser). ``pytest -m "not exudyn and not slow"`` runs the pure layers
alone in seconds; then Exudyn cannot be imported at all, so a test that needs it and is not marked
fails by name instead of passing unnoticed."""
import importlib.abc
import signal
import sys

import pytest

from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model

# A test suite started in the background of a non-interactive shell (`cmd &`, nohup) inherits SIGINT
# ignored, and so would every exubio it starts: the tests of Ctrl-C (SIGINT sent to a child, exit
# 130 expected) would see runs that never notice it. The tests need SIGINT deliverable: the default
# handler here, so the children start with the default disposition.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


class _NoExudyn(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "exudyn" or name.startswith("exudyn."):
            raise ImportError("exudyn is blocked: this test runs the PF engine, mark it @pytest.mark.exudyn")
        return None


# Test modules that run the PF engine (Exudyn), and the slow end-to-end ones: every test in them
# carries the marker. A module importing the PF method at its top is left uncollected when exudyn
# is deselected (it could not even be imported).
EXUDYN = {"test_angle_status.py", "test_api.py", "test_api_files.py", "test_session_folder.py", "test_api_face.py", "test_arms.py", "test_atomic_results.py",
          "test_calibrate.py", "test_cli.py", "test_exudyn_system.py", "test_hold.py", "test_live.py", "test_ls.py",
          "test_mismatch.py", "test_pf.py", "test_quality.py", "test_rates.py", "test_real_data.py", "test_report.py",
          "test_run_once.py", "test_streaming.py", "test_study.py", "test_thorax_check.py", "test_trial_report.py",
          "test_viewer.py", "test_same_outputs.py", "test_resume.py", "test_dynamics_truth.py", "test_study_table.py"}
SLOW = {"test_marker_sets.py", "test_atomic_results.py", "test_session_folder.py", "test_cli.py", "test_labels.py", "test_permutation.py", "test_real_data.py",
        "test_session_check.py", "test_study.py", "test_viewer.py", "test_same_outputs.py", "test_resume.py",
        "test_study_table.py"}


def _blocking(config) -> bool:
    return "not exudyn" in (config.option.markexpr or "")


def pytest_configure(config):
    if _blocking(config):
        sys.meta_path.insert(0, _NoExudyn())


def pytest_ignore_collect(collection_path, config):
    return True if _blocking(config) and collection_path.name in EXUDYN else None


def pytest_collection_modifyitems(config, items):
    for item in items:
        name = item.path.name
        if name in EXUDYN:
            item.add_marker(pytest.mark.exudyn)
        if name in SLOW:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(scope="module")
def model():
    return load_model()


@pytest.fixture(scope="module")
def kin(model):
    return Kinematics(model)


@pytest.fixture
def make_report():
    """A CalibrationReport with the given fields (the rest empty): the calibration checks of
    exubio.trust.quality read nothing else."""
    import numpy as np

    from exubio.calibration.report import CalibrationReport

    def make(**fields):
        base = dict(source="", frames=(0, 1, 1), frames_chosen_automatically=False, rate_hz=100.0, body_mass_kg=70.0,
                    generic_model="", protocol="", scale_factors={}, thorax_scale_measured=False,
                    static_q_rad=np.zeros(0), coordinate_names=(), ellipsoid_centre_m=np.zeros(3),
                    ellipsoid_radii_m=np.ones(3), ellipsoid_scale=1.0, constraint_abs=0.0, markers=(), fit_iterations=0)
        return CalibrationReport(**{**base, **fields})

    return make
