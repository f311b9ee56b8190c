"""The binding of a model and a protocol (exubio.protocol.bind): its facts equal what they are
computed from, each is computed once and held, it travels pickled with what it holds, and a run
takes the session's binding instead of building its own."""
from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import numpy as np
import pytest

from exubio.model.kinematics import Kinematics
from exubio.model.load import load_model
from exubio.protocol.bind import Binding, bind, held_mask, tracked_points
from exubio.run.inputs import load_session, protocol_for_model


@pytest.fixture(scope="module")
def model():
    return load_model()


@pytest.fixture(scope="module")
def thoracoscapular(model):
    return protocol_for_model(model, "thoracoscapular_9")  # holds sc_posterior_rotation, no forearm or hand markers


def test_facts_equal_what_they_are_computed_from(model, thoracoscapular):
    b = bind(model, thoracoscapular)
    kin = Kinematics(model)
    pts = tracked_points(kin, thoracoscapular)
    assert b.points.names == thoracoscapular.marker_names == pts.names
    np.testing.assert_array_equal(b.points.segment_index, pts.segment_index)
    np.testing.assert_array_equal(b.points.local_m, pts.local_m)
    names = model.coordinate_names
    assert [n for n, h in zip(names, b.held) if h] == ["sc_posterior_rotation"]
    np.testing.assert_array_equal(b.held, held_mask(model, thoracoscapular))
    # no marker on the ulna, radius or hand: their joints are locked, neither method solves them
    assert {model.segment_names[i] for i in b.unobserved} == {"ulna", "radius", "hand"}
    locked = {n for s in model.segments if s.name in ("ulna", "radius", "hand") for n in s.joint.coordinates}
    assert set(b.not_solved_names) == locked | {"sc_posterior_rotation"}
    assert not (b.locked & b.held).any() and ((b.locked | b.held) == b.not_solved).all()
    for a in (b.held, b.not_solved):
        assert not a.flags.writeable  # shared by every trial of the session
    q = np.random.default_rng(3).uniform(-0.5, 0.5, (4, model.n_coordinates))
    np.testing.assert_array_equal(b.kin.points(q, b.points), kin.points(q, pts))


def test_a_fact_is_kept_and_rebinding_shares_only_the_models(model, thoracoscapular):
    from exubio.trust.assess import angle_status_of_protocol, reference_postures_of

    full = bind(model, protocol_for_model(model))
    assert full.fact("pair") is None and full.keep("pair", 1) == 1 and full.fact("pair") == 1
    assert full.keep("model", 2, of_model=True) == 2 and full.fact("model", of_model=True) == 2
    other = full.rebound(thoracoscapular)
    assert other.model is full.model and other.protocol is thoracoscapular
    assert other.fact("model", of_model=True) == 2 and other.fact("pair") is None  # the model's: shared
    q = reference_postures_of(full)
    assert reference_postures_of(full) is q and reference_postures_of(other) is q  # computed once, of the model
    status = angle_status_of_protocol(full)
    assert angle_status_of_protocol(other) != status  # the pair's: its own (no forearm markers)
    assert full.rebound(full.protocol) is full
    assert bind(model, full.protocol) != full  # equal only to itself: no content comparison


def test_it_pickles_with_what_it_holds(model):
    from exubio.trust.assess import angle_status_of_protocol, reference_postures_of

    b = bind(model, protocol_for_model(model))
    status = angle_status_of_protocol(b)
    postures = reference_postures_of(b)
    _ = b.kin, b.not_solved
    state = pickle.dumps(b)
    assert len(state) < 200_000  # the kinematics is rebuilt, not carried
    c = pickle.loads(state)
    assert isinstance(c, Binding) and "kin" not in c.__dict__
    assert reference_postures_of(c) is not postures and np.array_equal(reference_postures_of(c), postures)
    held = c._model_facts  # what it held travels: asking again computes nothing
    assert angle_status_of_protocol(c) == status and c._model_facts is held
    np.testing.assert_array_equal(c.not_solved, b.not_solved)
    np.testing.assert_array_equal(c.kin.points(np.zeros(13), c.points), b.kin.points(np.zeros(13), b.points))


def test_a_session_carries_one_binding_and_its_trials_take_it(tmp_path):
    from exubio.io.resources import shipped_file
    from exubio.run.pipeline import load_inputs

    session = load_session()
    assert session.binding is session.binding and session.generic_binding is session.binding
    assert session.binding.model is session.model and session.binding.protocol is session.protocol
    inputs = load_inputs(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"), session)
    assert inputs.binding is session.binding  # no marker dropped: the session's own
    copy = pickle.loads(pickle.dumps(session))
    assert copy.generic_binding is copy.binding
    # a calibrated model: its own binding; the label checks' generic one (and what it holds) is kept
    model = dataclasses.replace(session.model, metadata={**session.model.metadata, "calibration": {"generic_model": ""}})
    calibrated = session.with_model(model)
    assert calibrated.binding.model is model and calibrated.binding is not session.binding
    assert calibrated.generic_binding is session.generic_binding
    assert calibrated.replaced(model=model).generic_binding is session.generic_binding


def test_a_run_takes_the_sessions_kinematics(monkeypatch, tmp_path):
    """With the session's binding built, a trial's run (LS, its checks, its files) builds the session
    model's kinematics again only in the two checks that take a model rather than the binding."""
    import traceback

    from exubio.io.resources import shipped_file
    from exubio.run.pipeline import reconstruct_file

    session = load_session()
    assert session.binding.kin.model is session.model
    callers = []
    init = Kinematics.__init__

    def spy(self, model, *args, **kwargs):
        if model is session.model:
            callers.append(Path(traceback.extract_stack(limit=2)[0].filename).name)
        return init(self, model, *args, **kwargs)

    monkeypatch.setattr(Kinematics, "__init__", spy)
    reconstruct_file(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"), tmp_path, methods=["ls"],
                     session=session)
    assert sorted(callers) == ["label_chains.py", "thorax_check.py"]
