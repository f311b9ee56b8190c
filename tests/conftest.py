"""Fixtures shared by the test modules (the generic model and its kinematics), and the markers that
show the layers: ``exudyn`` (the test runs the PF engine) and ``slow`` (an end-to-end run: the CLI,
a study, the real trials, a browser). Each test module declares its own (``pytestmark`` at its top,
or a decorator on one test); nothing here keeps a list. ``pytest -m "not exudyn and not slow"`` runs the pure layers
alone in seconds; then Exudyn cannot be imported at all, so a test that needs it and is not marked
fails by name instead of passing unnoticed."""
import ast
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


def _declared_markers(path) -> set[str]:
    """The markers a test module declares for all its tests (``pytestmark = ...`` at its top), read
    from its source without importing it: a module that imports the PF engine at its top could not
    even be imported with Exudyn blocked."""
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError):
        return set()
    found: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
            found |= {n.attr for n in ast.walk(node.value) if isinstance(n, ast.Attribute)
                      and isinstance(n.value, ast.Attribute) and n.value.attr == "mark"}
    return found


def _blocking(config) -> bool:
    return "not exudyn" in (config.option.markexpr or "")


def pytest_configure(config):
    if _blocking(config):
        sys.meta_path.insert(0, _NoExudyn())


def pytest_ignore_collect(collection_path, config):
    """With Exudyn deselected, a module that declares ``pytest.mark.exudyn`` is not even imported."""
    if _blocking(config) and collection_path.suffix == ".py" and collection_path.name.startswith("test_"):
        return True if "exudyn" in _declared_markers(collection_path) else None
    return None


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
