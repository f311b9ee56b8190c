"""A live session's recording written as ``exubio reconstruct`` writes a trial, atomically.

``<out>/<name>/`` holds: ``<name>.c3d`` (the input markers as received, lab frame, mm; frames that
never came are missing), ``<name>.markers.npz`` (the same in float64 m with the sample timestamps,
so the offline causal run can be repeated bit for bit), the result files of
``exubio reconstruct`` for PF (``<name>.pf.csv``, ``.mot``, ``.npz``,
``.summary.json``: the offline assessment of the recording, the same checks as a trial's), the
trial report (``<name>.report.pdf`` / ``.png``, unless ``report=False``) and ``<name>.live.json``
(the live events, the loop's figures, the running verdict at the end). Everything is written in a
hidden temporary folder beside it, renamed into place when complete: the folder is whole or
absent.
"""
from __future__ import annotations

import os
import secrets
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from exubio.errors import InputError
from exubio.io.records import to_json
from exubio.run.live.outputs import LiveRecording

__all__ = ["write_recording", "read_recorded_markers"]


def write_recording(rec: LiveRecording, out_dir: str | os.PathLike, name: str, /, *, overwrite: bool = False,
                    report: bool = True) -> Path:
    """Write the recording into ``out_dir/name`` (see the module docstring); returns that folder."""
    from exubio.protocol.bind import bind
    from exubio.trust.assess import TrialContext, assess_trial, trial_label_findings
    from exubio.io.c3d import write_c3d
    from exubio.io.results import atomic_write, write_json, writable_folder
    from exubio.run.pipeline import TrialInfo, TrialInputs, write_assessed
    from exubio.run.summary_file import RunNotes
    from exubio.types import Method
    from exubio.run.inputs import generic_of

    out = writable_folder(out_dir, label="--out")
    final = out / name
    if final.exists() and not overwrite:
        raise InputError(f"{final}: a recording of that name exists; pass --overwrite or another --name")
    if rec.n_frames < 2:
        raise InputError(f"{rec.info.name}: only {rec.n_frames} frame(s) came; nothing to write")
    tmp = out / f".{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    tmp.mkdir()
    try:
        traj = rec.trajectories()
        write_c3d(tmp / f"{name}.c3d", traj)

        def markers(path: Path) -> None:
            with open(path, "wb") as fh:
                np.savez(fh, raw_m=rec.raw_m, labels=np.array(rec.info.labels), timestamps_s=rec.timestamps_s,
                         rate_hz=np.array(rec.info.rate_hz), units=np.array(rec.info.units),
                         active=rec.active, run=rec.run)

        atomic_write(tmp / f"{name}.markers.npz", markers)
        targets = rec.targets()
        binding = bind(rec.model, rec.protocol)
        inputs = TrialInputs(TrialInfo(source=f"{name}.c3d", labels=rec.info.labels, ignored_labels=(),
                                       units_in_file=rec.info.units, rate_hz=rec.info.rate_hz), binding, targets)
        recon = rec.reconstruction()
        findings = trial_label_findings(bind(*generic_of(rec.model, rec.protocol)), targets)
        assessment = assess_trial(binding, targets, [recon],
                                  context=TrialContext(label_findings=tuple(findings), calibration=rec.calibration))
        live = live_summary(rec)
        outputs = write_assessed(inputs, f"{name}.c3d", tmp, [(Method.PF, f"{name}.pf", recon, None)], assessment,
                                 notes=RunNotes(live=live))
        write_json(tmp / f"{name}.live.json", {**live, "offline_verdict": to_json(assessment.quality["pf"])})
        if report:
            from exubio.report.trial_report import draw_trial_report
            from exubio.run.outcome import reported

            draw_trial_report([reported(outputs[0])], tmp / f"{name}.report.pdf")
        if final.exists():  # overwrite: the old folder goes only once the new one is complete
            old = out / f".{name}.{os.getpid()}.{secrets.token_hex(4)}.old"
            os.replace(final, old)
            os.replace(tmp, final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return final


def live_summary(rec: LiveRecording) -> dict[str, Any]:
    """What the live loop saw: the stream, the settings, its figures, the events, the verdict."""
    return {
        "stream": {"name": rec.info.name, "source_id": rec.info.source_id, "rate_hz": rec.info.rate_hz,
                   "units": rec.info.units, "labels": list(rec.info.labels)},
        "ended_by": rec.ended_by,
        "processing": rec.options.causal.describe() + "; PF one step per frame"
                      + ("" if rec.options.pf.project_constraints else ", no final projection on the constraints"),
        "figures": rec.stats,
        "live_verdict": to_json(rec.live_quality),
        "events": to_json(rec.events),
    }


def read_recorded_markers(path: str | os.PathLike, /):
    """The input markers of a recording (``<name>.markers.npz``) as a Trajectories (float64, m)."""
    from exubio.types import Trajectories

    with np.load(path) as z:
        labels = tuple(str(x) for x in z["labels"])
        raw, rate = z["raw_m"], float(z["rate_hz"])
    return Trajectories(labels=labels, positions_m=raw, rate_hz=rate, time_s=np.arange(raw.shape[0]) / rate,
                        source=str(path), units_in_file="m")
