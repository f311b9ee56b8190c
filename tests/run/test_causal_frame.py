"""The compiled causal frame (exubio.model.batch_kernels.causal_frame) gives bit for bit what the Python
path of ``CausalTargets`` gives, frame after frame and with the same state carried: the thorax frame from
IJ, PX, C7, T8 or from the midpoints, a left arm mirrored, no thorax frame at all, markers missing
(a coordinate, a frame, the whole trial), a thorax landmark missing for a few frames (held: the Python
path), collinear landmarks and a restart."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from exubio.io.resources import shipped_file
from exubio.io.trial import read_trial
from exubio.run.inputs import load_model_and_protocol
from exubio.run.live.causal import CausalTargets
from exubio.types import ThoraxFrameSpec


def _stream(form: str):
    """(protocol, labels, frames (n, n_labels, 3) m) of the shipped example, faults injected."""
    _, protocol = load_model_and_protocol()
    t = read_trial(shipped_file("exubio.data", "example_abduction.c3d", "exubio/data"))
    labels, pos = list(t.labels), t.positions_m[:120].copy()
    tf = protocol.thorax_frame
    if form == "midpoints":
        col = {lab: i for i, lab in enumerate(labels)}
        up = 0.5 * (pos[:, col[tf.ij]] + pos[:, col[tf.c7]])
        low = 0.5 * (pos[:, col[tf.px]] + pos[:, col[tf.t8]])
        labels += ["UP_MID", "LOW_MID"]
        pos = np.concatenate([pos, up[:, None], low[:, None]], axis=1)
        protocol = dataclasses.replace(protocol, thorax_frame=ThoraxFrameSpec(ij=tf.ij, ij_c7_midpoint="UP_MID",
                                                                              px_t8_midpoint="LOW_MID"))
    elif form == "left":
        protocol = dataclasses.replace(protocol, side="left")
    elif form == "identity":
        protocol = dataclasses.replace(protocol, thorax_frame=ThoraxFrameSpec())
    pos[:, labels.index(protocol.marker_names[3])] = np.nan  # a marker missing in every frame
    rng = np.random.default_rng(7)
    for f in rng.choice(np.arange(5, 120), 30, replace=False):  # markers missing, one coordinate or all
        j = rng.integers(len(labels))
        pos[f, j, rng.integers(3)] = np.nan
    if form != "identity":
        ij = labels.index(protocol.thorax_frame.ij)
        pos[40:43, ij] = np.nan  # a landmark missing for three frames: held at its last value
        pos[70, :, :] = pos[70, ij]  # every label on IJ: collinear landmarks, no thorax frame
    return protocol, labels, pos


@pytest.mark.parametrize("form", ["four", "midpoints", "left", "identity"])
def test_the_compiled_frame_is_the_python_path(form):
    protocol, labels, pos = _stream(form)
    compiled = CausalTargets(protocol, labels, 100.0)
    python = CausalTargets(protocol, labels, 100.0)
    python._kernel = None
    assert compiled._kernel is not None
    held = 0
    for i, raw in enumerate(pos):
        if i == 90:
            compiled.restart()
            python.restart()
        a, b = compiled.push(raw), python.push(raw)
        np.testing.assert_array_equal(a.present, b.present, err_msg=f"frame {i}")
        for x, y in ((a.positions_m, b.positions_m), (a.velocities_m_s, b.velocities_m_s),
                     (a.accelerations_m_s2, b.accelerations_m_s2)):
            np.testing.assert_array_equal(x, y, err_msg=f"frame {i}")  # NaN where both are NaN
        held += form != "identity" and 40 <= i < 43 and bool(a.present.any())
    assert form == "identity" or held == 3  # the held landmark kept the frame in both
    if form != "identity":
        assert not compiled.push(pos[70]).present.any()  # no thorax frame: every marker missing
