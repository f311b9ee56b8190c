"""The TRC subject's glenohumeral centre and humerus length from exubio's calibration against the
subject's own thoracoscapular model (issue "Subject calibration", must-show 2).

The reference: ../shared/data/models/rmr_TSM_subject_noWeight.osim (Seth et al. 2019, subject-scaled),
fitted by marker inverse kinematics (models/sources/tsm_geometry.py: all 9 TRC markers, the AC
constraint) to the mean of the same frames exubio calibrates on (0:50, arm hanging still): its
GH centre and elbow centre, expressed in the ISB thorax frame that exubio builds from the TRC's ij,
centijc7 and centpxt8. exubio: the calibrated model's joint centres at its static pose
(CalibrationReport.joint_centres_mm), with the generic glenohumeral centre placed from the scapula
markers, and with SCoRE on the trial itself (--functional: the abduction or flexion of the same
trial). Prints the distances (mm) and lengths; the aim was GH within 10 mm, length within 5 %.

Usage: python studies/calibration_trc_vs_tsm.py
"""
from __future__ import annotations

import importlib.util
import logging
import sys
from pathlib import Path

import numpy as np

from exubio.calibration import calibrate_model
from exubio.io.trial import read_trial
from exubio.run.inputs import load_model_and_protocol
from exubio.prep.targets import prepare_targets

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
FRAMES = slice(0, 50)


def _tsm_module():
    spec = importlib.util.spec_from_file_location("tsm_geometry", ROOT / "models" / "sources" / "tsm_geometry.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["tsm_geometry"] = mod
    spec.loader.exec_module(mod)
    return mod


def reference(tg, trc: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """(GH, elbow centre) of the subject's model fitted to the mean of FRAMES, mm in the ISB thorax
    frame of the TRC markers, and the fit's marker RMS (mm)."""
    tsm = tg.load_tsm(SHARED / "models" / "rmr_TSM_subject_noWeight.osim")
    labels, pos, _ = tg.read_trc(trc)
    mean = np.nanmean(pos[FRAMES], axis=0) / 1000.0
    targets = {n: mean[i] for i, n in enumerate(labels) if n in tsm.markers}
    q, rms = tg.fit_markers(tsm, targets, tg.assemble(tsm))
    pts = tg.posture_points(tsm, q)
    gh, elbow = pts["GH_centre"], pts["elbow_centre"]  # the glenohumeral and elbow joint centres
    ij, c7m, pt8 = (mean[labels.index(n)] for n in ("ij", "centijc7", "centpxt8"))
    X = tg.isb_thorax_frame(ij, 2 * c7m - ij, pt8, pt8)
    to_isb = lambda p: X.R.T @ (np.asarray(p) - X.p) * 1000.0  # noqa: E731
    return to_isb(gh), to_isb(elbow), rms * 1000.0


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to run", file=sys.stderr)
        return 2
    tg = _tsm_module()
    protocol_path = ROOT / "protocols" / "thoracoscapular_9.yaml"
    for name in ("ABD01", "FLX01"):
        trc = SHARED / "trc" / f"tsm_rmr_{name}.trc"
        gh_ref, el_ref, rms = reference(tg, trc)
        len_ref = float(np.linalg.norm(gh_ref - el_ref))
        print(f"{trc.name}: subject's model fitted to frames 0:50, marker RMS {rms:.1f} mm; GH "
              f"{np.round(gh_ref, 1).tolist()} mm, humerus GH-elbow centre {len_ref:.1f} mm")
        model, protocol = load_model_and_protocol(protocol_path=protocol_path)
        traj = read_trial(trc)
        for label, functional in (("marker fit", None), ("SCoRE on the trial", prepare_targets(traj, protocol))):
            cal, rep = calibrate_model(model, protocol, traj, frames=FRAMES, functional=functional)
            gh = np.array(rep.joint_centres_mm["gh"])
            el = np.array(rep.joint_centres_mm["elbow"])
            length = float(np.linalg.norm(gh - el))
            note = ""
            if functional is not None:
                info = rep.functional.get("gh", {})
                note = (f" (SCoRE: {info.get('rotation_range_deg', float('nan')):.0f} deg range, RMS "
                        f"{info.get('rms_mm', float('nan')):.1f} mm)" if info.get("used") else f" (not used: {info.get('reason')})")
            print(f"  exubio, GH from the {label}{note}: GH {np.round(gh, 1).tolist()} mm, {np.linalg.norm(gh - gh_ref):.1f} mm "
                  f"from the subject's model; humerus {length:.1f} mm ({100 * (length / len_ref - 1):+.1f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
