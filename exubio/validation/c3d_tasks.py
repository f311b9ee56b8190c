"""Fig. 5 (C3D tasks): the 21-marker C3D task trials (free movements, not planar elevations),
each calibrated on its session's static trial, PF and LS, compared with Ludewig et al. 2009 and
the corridor in every plane of elevation their raising phases match, or why not."""
from __future__ import annotations

from exubio.errors import ExubioError
from exubio.literature.invivo import PLANE_TOLERANCE_DEG, RAISING_MIN_SPAN_DEG, compare_elevation, inferred_joints
from exubio.io.trial import read_trial
from exubio.run.inputs import load_session
from exubio.run.session import calibrate_file
from exubio.prep.targets import prepare_targets
from exubio.io.resources import shipped_file
from exubio.io.records import decode
from exubio.validation.determinacy import trial_undetermined, undetermined_isb
from exubio.validation.paths import shared_data_dir
from exubio.validation.results import METHODS, C3dTask, C3dTasks, InvivoComparison, Skipped, TrialData
from exubio.validation.settings import ValidationSettings
from exubio.validation.trials import Progress, Trial, run_method

__all__ = ["C3D_TASKS", "c3d_task_comparison"]

# the 21-marker C3D task trials with the static trial of their session (../shared/data/SOURCES.md)
C3D_TASKS = (("bioptim_exo_martin_dynamique.c3d", "bioptim_exo_martin_statique.c3d", None),
             *((f"bioptim_exo_kinova_martin_{n}_f3_1.c3d", "bioptim_exo_kinova_martin_statique.c3d",
                "examples/kinova_martin_session.yaml") for n in ("aisselle", "dent", "manger", "tete")))


def c3d_task_comparison(s: ValidationSettings, progress: Progress) -> C3dTasks | Skipped:
    """Each C3D task trial compared in every reference plane where its raising frames (plane of
    elevation within exubio.literature.invivo.PLANE_TOLERANCE_DEG) cover at least RAISING_MIN_SPAN_DEG of HT
    elevation above 30 deg; otherwise the reason."""
    if not s.c3d_tasks:
        return Skipped(skipped="not run in this run (ValidationSettings.c3d_tasks is False)")
    c3d = shared_data_dir() / "c3d"
    trials: dict[str, C3dTask | Skipped] = {}
    for trial, static, protocol in C3D_TASKS:
        if not (c3d / trial).is_file() or not (c3d / static).is_file():
            trials[trial] = Skipped(skipped=f"{c3d / trial} or its static {static} is not available")
            continue
        progress(f"C3D task {trial}: calibrating on {static}, PF and LS")
        try:
            proto_path = shipped_file("exubio.protocols", protocol, "protocols") if protocol else None
            model, proto, _ = calibrate_file(c3d / static, session=load_session(protocol_path=proto_path))
            targets = prepare_targets(read_trial(c3d / trial), proto)
        except ExubioError as exc:
            trials[trial] = Skipped(skipped=f"could not be prepared: {exc}")
            continue
        tr = Trial(trial, model, proto, targets, TrialData(kind="real", frames=targets.n_frames, protocol=proto.name,
                                                           model=model.name))
        for method in METHODS:
            run_method(tr, method, progress)
        qs = {m: (r.q_rad if r is not None else None) for m, r in tr.recon.items()}
        matched: dict[str, InvivoComparison] = {}
        not_matched: dict[str, str] = {}
        und, inf = undetermined_isb(trial_undetermined(tr)), inferred_joints(model, proto)
        for plane in ("frontal", "scapular", "sagittal"):
            res, _ = compare_elevation(model, qs, targets.time_s, plane, undetermined=und, inferred=inf,
                                       plane_tolerance_deg=PLANE_TOLERANCE_DEG)
            ref = res.get("ls") or res.get("pf") or {}
            span = ref.get("raising_ht_range_deg")
            lo = max(span[0], 30.0) if span else float("nan")
            if span and span[1] - lo >= RAISING_MIN_SPAN_DEG:
                res.pop("definitions", None)
                matched[plane] = decode(InvivoComparison, res)
            else:
                not_matched[plane] = (
                    f"HT elevation reaches {ref.get('ht_range_deg', [0, float('nan')])[1]:.0f} deg; raising frames within "
                    f"{PLANE_TOLERANCE_DEG:g} deg of the {plane} plane cover "
                    + (f"HT {span[0]:.0f}-{span[1]:.0f} deg, less than {RAISING_MIN_SPAN_DEG:g} deg above HT 30" if span
                       else f"nothing: no raising phase (HT rising over at least {RAISING_MIN_SPAN_DEG:g} deg)"))
        trials[trial] = C3dTask(static=static, protocol=proto.name, frames=targets.n_frames, errors=dict(tr.errors),
                                matched=matched, not_matched=not_matched)
    return C3dTasks(plane_tolerance_deg=PLANE_TOLERANCE_DEG, min_span_deg=RAISING_MIN_SPAN_DEG, trials=trials)
