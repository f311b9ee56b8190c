"""One serialisation scheme (exubio.io.records): a typed record written and read back equals
itself, its field options (converted units, rounding, internal and optional fields, enums) do what
the module docstring says, and the summary.json of a real run decodes into the typed results
(exubio.run.summary_record) and writes the same bytes again."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from exubio.cli import main
from exubio.io.records import SchemaError, converted, decode, encode_arrays, internal, nan_to_none, optional, to_json
from exubio.io.results import write_json
from exubio.model.ranges import LimitReport
from exubio.run.live.outputs import Event
from exubio.run.summary_record import ReconstructionSummary, TrialSummary
from exubio.trust.labels import LabelFinding
from exubio.trust.mismatch import MismatchAssessment, MismatchFinding, SegmentEvidence
from exubio.trust.quality import Quality, Reason
from exubio.types import Severity, Verdict

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "c3d"
EXAMPLE = ROOT / "exubio" / "data" / "example_abduction.c3d"


def _text(data) -> str:
    """The bytes exubio writes for ``data`` (exubio.io.results.write_json's text)."""
    return json.dumps(nan_to_none(data), indent=2, allow_nan=False) + "\n"


@dataclass(frozen=True)
class _Pose:
    name: str
    angle_rad: float = converted(write=np.degrees, read=np.radians, digits=4)
    centre_m: np.ndarray = converted(write=lambda v: v * 1000.0, read=lambda v: v / 1000.0, default=None)
    level: Severity = Severity.NOTE
    scratch: float = internal(default=0.0)
    note: str | None = optional()
    tags: tuple[str, ...] | None = optional(empty=True)


def test_a_typed_record_written_and_read_back_equals_itself():
    q = Quality.of([Reason("residual", "check", "mean residual 9 mm"), Reason("input_file", Severity.NOTE, "x")])
    back = decode(Quality, json.loads(_text(to_json(q))))
    assert back == q and isinstance(back.verdict, Verdict) and all(isinstance(r.level, Severity) for r in back.reasons)
    assert to_json(q) == {"verdict": "check", "reasons": [{"code": "residual", "level": "check", "message": "mean residual 9 mm"},
                                                          {"code": "input_file", "level": "note", "message": "x"}]}
    lim = LimitReport("gh_flexion", (-80.0, 160.0), 13, 552, 0.25)
    assert decode(LimitReport, json.loads(_text(to_json(lim)))) == lim
    assert to_json(lim)["range_deg"] == [-80.0, 160.0]
    ev = Event("gap", 10, 0.1234567891, "marker EPI_lat missing", ("EPI_lat",))
    assert to_json(ev)["time_s"] == 0.123457  # to the µs
    assert decode(Event, to_json(ev)) == Event("gap", 10, 0.123457, "marker EPI_lat missing", ("EPI_lat",))
    finding = LabelFinding("swap", ("A", "B"), "A and B look swapped", "error")
    assert decode(LabelFinding, to_json(finding)) == finding


def test_field_options_convert_round_omit_and_keep_in_memory():
    pose = _Pose("static", angle_rad=math.radians(30.123456), centre_m=np.array([0.1, -0.02, 0.0031]), scratch=7.0)
    data = to_json(pose)
    assert data == {"name": "static", "angle_rad": 30.1235, "centre_m": [100.0, -20.0, 3.1], "level": "note"}
    assert encode_arrays(pose) == {}  # a converted array is written in the JSON, not the npz archive
    back = decode(_Pose, json.loads(_text(data)))
    assert back.scratch == 0.0 and back.note is None and back.tags is None  # internal: default; optional: absent
    assert back.angle_rad == pytest.approx(math.radians(30.1235), abs=1e-15)
    np.testing.assert_allclose(back.centre_m, [0.1, -0.02, 0.0031], rtol=0, atol=1e-15)
    assert _text(to_json(back)) == _text(data)  # a rounded file reads back to what writes the same bytes
    assert "tags" not in to_json(_Pose("x", 0.0, tags=())) and to_json(_Pose("x", 0.0, tags=("a",)))["tags"] == ["a"]
    with pytest.raises(SchemaError, match="level.*'note', 'check', 'fail'.*'maybe'"):
        decode(_Pose, {**data, "level": "maybe"})
    with pytest.raises(SchemaError, match="unknown key.*'scratch'"):
        decode(_Pose, {**data, "scratch": 1.0})  # an internal field is not in the file


def test_rounded_evidence_and_a_summary_exception_round_trip():
    ev = SegmentEvidence("scapula", ("A", "B", "C"), 40, 3.14159, 1.23456, "A", 2.71828, contact_offset_mm=float("nan"))
    assert to_json(ev)["residual_rms_mm"] == 3.142 and to_json(ev)["pose_gap_deg"] is None
    finding = MismatchFinding("scapula", "off the ellipsoid", pose_gap_deg=4.567, normal_mm=None, contact_offset_mm=9.0)
    assert "contact_offset_mm" not in to_json(finding)  # kept in memory, in the evidence beside it
    mm = MismatchAssessment({"scapula": ev}, (finding,))
    text = _text(to_json(mm))  # through its hand-kept to_dict: the definition first, the evidence as a list
    back = decode(MismatchAssessment, json.loads(text))
    assert _text(to_json(back)) == text and back.findings[0].pose_gap_deg == 4.57
    assert list(back.evidence) == ["scapula"] and back.evidence["scapula"].bias_mm == 1.235


def _summaries(tmp_path: Path, *args: str) -> list[Path]:
    assert main(["-q", "reconstruct", *args, "--method", "ls", "--no-report", "--out", str(tmp_path)]) in (0, 1)
    return sorted(tmp_path.glob("*.summary.json"))


@pytest.mark.parametrize("static", [False, True, "frames"], ids=["example", "calibrated_real_trial", "real_trial_at_a_limit"])
def test_a_real_runs_summary_decodes_into_typed_results_and_writes_the_same_bytes(tmp_path, static):
    """``exubio reconstruct`` (LS, no Exudyn) of the shipped example, of a real trial with its
    session's static (the calibration section, label findings) and of one calibrated on its first frames
    (with limits; both skipped without ../shared/data): summary.json -> TrialSummary -> the same text,
    byte for byte."""
    if static == "frames":  # calibrated on its own first frames: sc_posterior_rotation rests on its limit
        trial = DATA / "bioptim_exo_F0_boire_05.c3d"
        if not trial.is_file():
            pytest.skip("the shared real data (../shared/data) is absent")
        paths = _summaries(tmp_path, str(trial), "--static-frames", "0:20")
    elif static:
        trial, stat = DATA / "bioptim_exo_martin_dynamique.c3d", DATA / "bioptim_exo_martin_statique.c3d"
        if not (trial.is_file() and stat.is_file()):
            pytest.skip("the shared real data (../shared/data) is absent")
        paths = _summaries(tmp_path, str(trial), "--static", str(stat))
    else:
        paths = _summaries(tmp_path, str(EXAMPLE))
    assert len(paths) == 1
    text = paths[0].read_text(encoding="utf-8")
    summary = decode(TrialSummary, json.loads(text))
    assert isinstance(summary.quality, Quality) and isinstance(summary.model_mismatch, MismatchAssessment)
    assert all(isinstance(lim, LimitReport) for lim in summary.limits)
    assert all(isinstance(f, LabelFinding) for f in summary.labels)
    assert summary.n_frames > 100 and summary.method == "ls"
    if static:
        assert summary.calibration is not None and bool(summary.limits) == (static == "frames")
        assert all(isinstance(f, LabelFinding) for f in summary.calibration.labels)
    write_json(tmp_path / "again.json", to_json(summary))
    assert (tmp_path / "again.json").read_text(encoding="utf-8") == text
    # a summary that is not one: the error names the key
    with pytest.raises(SchemaError, match="verdict"):
        decode(TrialSummary, {**json.loads(text), "quality": {"reasons": []}})


def test_a_reconstruction_written_on_its_own_decodes_and_writes_the_same_bytes(tmp_path):
    """exubio.write_results without the trial: the ReconstructionSummary record, its verdict typed."""
    import exubio

    rec = exubio.reconstruct(exubio.read_trial(EXAMPLE), method="ls")
    paths = exubio.write_results(rec, tmp_path, "example")
    text = Path(paths["summary"]).read_text(encoding="utf-8")
    summary = decode(ReconstructionSummary, json.loads(text))
    assert summary.quality == rec.quality and summary.n_frames == rec.n_frames
    write_json(tmp_path / "again.json", to_json(summary))
    assert (tmp_path / "again.json").read_text(encoding="utf-8") == text
    with pytest.raises(SchemaError):
        decode(TrialSummary, json.loads(text))  # not a run's summary: its keys are missing
