"""Fixtures shared by the test modules: the generic model and its kinematics."""
import pytest

from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model


@pytest.fixture(scope="module")
def model():
    return load_model()


@pytest.fixture(scope="module")
def kin(model):
    return Kinematics(model)
