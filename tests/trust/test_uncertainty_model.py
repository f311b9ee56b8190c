"""A lab's own STA amplitude model, named by a protocol's ``uncertainty_model:`` key
(exubio.trust.sta_amplitude.amplitude_of): it is the model every uncertainty of a run with that
protocol is computed with, and the uncertainty follows it as first-order propagation says it must."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from exubio.api import load_model, load_protocol
from exubio.errors import InputError
from exubio.protocol.bind import bind
from exubio.trust import angle_uncertainty as AU
from exubio.trust.assess import angle_determinacy_of_protocol
from exubio.trust.sta_amplitude import amplitude_of, load_sta_amplitude, shipped_amplitude


def _scaled(k: float):
    """The shipped model with every skin and girdle amplitude times k (second moments times k^2)."""
    a = shipped_amplitude()
    sd = lambda d: {s: np.asarray(v) * k for s, v in d.items()}
    mom = lambda d: {s: np.asarray(v) * k * k for s, v in d.items()}
    return dataclasses.replace(a, rotation=sd(a.rotation), translation=sd(a.translation), nonrigid=sd(a.nonrigid),
                               rigid=mom(a.rigid), cross=mom(a.cross), girdle=a.girdle * k * k)


def _binding(tmp_path, k: float | None):
    """The generic model bound to the shipped protocol extended with ``uncertainty_model:`` naming a file
    of the shipped model scaled by k (None: no key)."""
    folder = tmp_path / f"k{k}"
    folder.mkdir()
    key = ""
    if k is not None:
        (folder / "lab_u.json").write_text(json.dumps(_scaled(k).to_json()))
        key = "uncertainty_model: lab_u.json\n"
    path = folder / "p.yaml"
    path.write_text("schema_version: 1\nextends: upper_limb_21\n" + key)
    model = load_model()
    return bind(model, load_protocol(path, model=model))


def test_the_protocols_file_is_the_runs_model_read_once_and_kept(tmp_path):
    b = _binding(tmp_path, 2.0)
    amp = amplitude_of(b)
    assert amp.path == str((tmp_path / "k2.0" / "lab_u.json").resolve())
    np.testing.assert_allclose(amp.rigid["scapula"], 4 * shipped_amplitude().rigid["scapula"], rtol=1e-5)
    assert amplitude_of(b) is amp
    assert amplitude_of(_binding(tmp_path, None)) is shipped_amplitude()


def test_the_uncertainty_follows_the_labs_model(tmp_path):
    """At the protocol's reference postures: with a model of no artefact and no girdle error, u is the
    marker noise through the reconstruction (NOISE_MM x the angle's noise gain); with every amplitude
    doubled, what the model adds to u^2 is four times what the shipped one adds. The status says which
    model it used only where it is a lab's."""
    dets = {k: angle_determinacy_of_protocol(_binding(tmp_path, k))[0] for k in (None, 0.0, 1.0, 2.0)}
    u = {k: np.degrees(d.uncertainty_rad) for k, d in dets.items()}
    gain = dets[0.0].gain_deg_per_mm
    ok = np.isfinite(u[0.0]) & np.isfinite(gain)
    assert ok.sum() > 100
    np.testing.assert_allclose(u[0.0][ok], AU.NOISE_MM * gain[ok], rtol=1e-9, atol=1e-9)
    ok = np.isfinite(u[0.0]) & np.isfinite(u[1.0]) & np.isfinite(u[2.0])
    added1, added2 = u[1.0][ok] ** 2 - u[0.0][ok] ** 2, u[2.0][ok] ** 2 - u[0.0][ok] ** 2
    assert added1.max() > 1.0  # deg^2: the artefact matters at these postures
    np.testing.assert_allclose(added2, 4 * added1, rtol=1e-4, atol=1e-6)  # the files hold 6 significant digits
    np.testing.assert_allclose(u[1.0], u[None], rtol=1e-5)  # the shipped numbers from a lab's file: the same u
    assert dets[None].uncertainty_model == "" and "uncertainty_model" not in dets[None].to_dict()
    assert dets[2.0].to_dict()["uncertainty_model"].startswith(str(tmp_path / "k2.0" / "lab_u.json"))


def test_a_file_that_is_not_a_model_is_one_error_naming_it(tmp_path):
    bad = tmp_path / "u.json"
    for wrong in ({"rotation": {"scapula": [1, 2]}}, {"rotation": 3}, [1, 2], "text"):
        bad.write_text(json.dumps(wrong))
        with pytest.raises(InputError, match=str(bad)):
            load_sta_amplitude(bad)
    bad.write_text(json.dumps({"rotation": {"scapula": [1, 2]}}))
    path = tmp_path / "p.yaml"
    path.write_text("schema_version: 1\nextends: upper_limb_21\nuncertainty_model: u.json\n")
    model = load_model()
    with pytest.raises(InputError, match="not an STA amplitude model"):
        amplitude_of(bind(model, load_protocol(path, model=model)))


def test_the_girdle_offset_and_a_labs_judgement_travel_with_the_file(tmp_path, capsys):
    """The girdle's offset theta_0 and the one-trial-out judgement ``exubio uncertainty-fit`` records come
    back from the file as written; a file from before the offset has none (theta_0 = 0, its u unchanged);
    an offset below zero is one error naming the file; ``exubio protocols`` says the lab's judgement."""
    from exubio.cli import main

    judged = {"method": "one trial out", "cells": 12, "below_90": 2, "above_99": 7,
              "trials": {"a.mat": {"ls_verdict": "ok", "angles": {"ST_X_upward_rotation": {"coverage": 0.8125,
                                                                                             "measured_fraction": 0.5}}}}}
    amp = dataclasses.replace(shipped_amplitude(), judgement=judged)
    path = tmp_path / "lab_u.json"
    path.write_text(json.dumps(amp.to_json()))
    back = load_sta_amplitude(path)
    assert back.judgement == judged and back.girdle_offset_rad == pytest.approx(shipped_amplitude().girdle_offset_rad)
    assert "on 1 trials: of 12 angle cells" in back.judgement_line() and "2 held the bone" in back.judgement_line()
    data = amp.to_json()
    del data["girdle_driver_offset_rad"]
    path.write_text(json.dumps(data))
    assert load_sta_amplitude(path).girdle_offset_rad == 0.0
    data["girdle_driver_offset_rad"] = -0.1
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=f"{path}.*girdle_driver_offset_rad"):
        load_sta_amplitude(path)
    path.write_text(json.dumps(amp.to_json()))
    (tmp_path / "p.yaml").write_text("schema_version: 1\nextends: upper_limb_21\nuncertainty_model: lab_u.json\n")
    assert main(["protocols", str(tmp_path / "p.yaml")]) == 0
    assert "judged one trial out on 1 trials: of 12 angle cells" in capsys.readouterr().out
