"""Studies: subjects x sessions x trials from one study file, run locally or on Dask, resumable.

A study file (YAML, paths relative to it) lists sessions (subject, protocol, model, static trial,
functional and scapula trials, static frames, trials by glob, relabellings) under ``sessions``:
``exubio study --template`` prints one with every key explained (exubio.run.study_template).

Results: ``OUT/<subject>/<session>/<trial>/`` holds one trial's result set (the files of
``exubio reconstruct``) and ``DONE.json`` (written last); the session's calibrated model is in
``OUT/<subject>/<session>/calibration/``. Two trials can never collide: the folder names the
subject, session and trial. A trial is processed in a hidden temporary folder beside its final one
and renamed into place when complete, so a result set appears whole or not at all; leftovers of a
killed run are removed by the next run, which skips the trials that are complete (resume).

``OUT/study.csv`` and ``OUT/study.json``: one row per trial (verdict per method, frames, mean
residual, PF-LS agreement, wall time, or the error); ``study.report.pdf``: the same table and the rhythm
pages; ``angles.parquet`` and ``angles.csv.gz``: every angle in one table (exubio.run.study_table);
with a session's ``body_mass_kg`` (or ``--body-mass``), ``moments.parquet`` and ``moments.csv.gz``: every
joint moment in one table (exubio.run.study_moments).

Execution: a local process pool (``jobs``), or Dask (``scheduler``: ``"local:N"`` starts a local
cluster of N workers, ``"tcp://HOST:PORT"`` uses a running scheduler). Workers are long-lived
processes that import exubio once. A trial's exception never stops the study.
"""
from __future__ import annotations

import dataclasses
import csv
import io
import json
import logging
import os
import shutil
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping

from exubio.io.result_names import SUFFIXES
from exubio.errors import ExubioError, InputError
from exubio.method_registry import method_names
from exubio.run import interrupt, study_table
from exubio.run.executors import run_all
from exubio.run.study_leftovers import _TMP_PREFIX, _remove_after_dask, clean_leftovers
from exubio.run.study_file import SessionSpec, StudySpec, load_study
from exubio.run.study_moments import moments_as_asked, write_moments_table

if TYPE_CHECKING:
    from exubio.run.job import TrialResult

log = logging.getLogger(__name__)

__all__ = ["StudySpec", "SessionSpec", "TrialTask", "TrialOutcome", "load_study", "run_study", "DONE_FILE",
           "STUDY_COLUMNS"]

DONE_FILE = "DONE.json"
def study_columns() -> tuple[str, ...]:
    """study.csv's columns: per method of exubio.method_registry its verdict and mean residual."""
    methods = method_names()
    return ("subject", "session", "trial", "status", *(f"{m}_verdict" for m in methods), "frames",
            *(f"{m}_residual_mm" for m in methods), "pf_ls_max_rmse_deg", "wall_s", "folder", "error", "reasons")


STUDY_COLUMNS = study_columns()
"""The columns with the shipped methods (pf, ls): study_columns() also lists a method added since."""


@dataclass(frozen=True)
class TrialTask:
    """One trial of a study to run: its place in the study and the job (exubio.run.job.TrialJob,
    run into a temporary folder beside ``final_dir``); picklable, the session's model and protocol
    travel inside the job as loaded objects."""

    subject: str
    session: str
    trial: str
    final_dir: str
    job: Any  # exubio.run.job.TrialJob


@dataclass
class TrialOutcome:
    subject: str
    session: str
    trial: str
    folder: str
    status: str  # "done", "skipped (complete)", "failed"
    verdicts: dict[str, str] = field(default_factory=dict)
    frames: int | None = None
    residual_mm: dict[str, float] = field(default_factory=dict)
    pf_ls_max_rmse_deg: float | None = None
    wall_s: float | None = None
    error: str = ""
    reasons: str = ""  # every check and fail reason of every method's verdict ("PF check: ...; LS fail: ...")

    def row(self) -> dict[str, Any]:
        methods = method_names()
        return {"subject": self.subject, "session": self.session, "trial": Path(self.trial).name,
                "status": self.status, **{f"{m}_verdict": self.verdicts.get(m, "") for m in methods},
                "frames": self.frames, **{f"{m}_residual_mm": self.residual_mm.get(m) for m in methods},
                "pf_ls_max_rmse_deg": self.pf_ls_max_rmse_deg, "wall_s": self.wall_s, "folder": self.folder,
                "error": self.error, "reasons": self.reasons}


# --------------------------------------------------------------------------------------------
# One trial (runs in a worker)
# --------------------------------------------------------------------------------------------
def run_trial_task(task: TrialTask) -> TrialOutcome:
    """Process one trial into a temporary folder beside its final one, write DONE.json last and
    rename the folder into place; any exception becomes a failed outcome (the study goes on)."""
    from exubio.run.job import run_job

    final = Path(task.final_dir)
    out = TrialOutcome(task.subject, task.session, task.trial, str(final), "failed")
    tmp = final.parent / f"{_TMP_PREFIX}{final.name}-{os.getpid()}-{time.monotonic_ns()}"
    t0 = time.perf_counter()
    from exubio.io.results import done_with, in_progress

    try:
        tmp.mkdir(parents=True)
        in_progress(tmp)
        result = run_job(dataclasses.replace(task.job, out_dir=tmp, final_dir=final))
        _fill(out, result)
        out.status = "done"
        out.wall_s = time.perf_counter() - t0
        _write_done(tmp, out, result)
        if final.exists():  # an incomplete set from an earlier run (no DONE.json): replaced
            shutil.rmtree(final)
        tmp.rename(final)
        done_with(tmp)
    except BaseException as exc:  # noqa: BLE001 - one trial's failure of any kind is recorded
        out.status = "failed"
        out.error = f"{type(exc).__name__}: {exc}" if not isinstance(exc, ExubioError) else str(exc)
        out.wall_s = time.perf_counter() - t0
        if not isinstance(exc, ExubioError):
            log.debug("%s", traceback.format_exc())
        shutil.rmtree(tmp, ignore_errors=True)
        done_with(tmp)
        if isinstance(exc, KeyboardInterrupt):
            raise
        if interrupt.pressed():  # Ctrl-C, as whatever Exudyn made of it: the study stops
            raise KeyboardInterrupt from exc
    return out


def _fill(out: TrialOutcome, result: TrialResult) -> None:
    out.verdicts = result.verdicts
    if result.failed:  # one method failed, the other's result is written
        out.error = "; ".join(f"{m.upper()} failed: {reason}" for m, reason in result.failed.items())
    out.reasons = verdict_reasons({m.method: m.summary for m in result.methods})
    for m in result.methods:
        out.frames = m.summary.get("n_frames", out.frames)
        out.residual_mm[m.method] = (m.summary.get("residual_mm") or {}).get("mean")
    agree = result.agreement_deg or {}
    out.pf_ls_max_rmse_deg = max(agree.values()) if agree else None


def verdict_reasons(summaries: Mapping[str, Mapping[str, Any]]) -> str:
    """Every check and fail reason of each method's verdict (its summary.json's quality), one string."""
    return "; ".join(f"{m.upper()} {r.get('level')}: {r.get('message')}" for m, s in summaries.items()
                     for r in (s.get("quality") or {}).get("reasons") or [] if r.get("level") in ("check", "fail"))


def _write_done(folder: Path, out: TrialOutcome, result: TrialResult) -> None:
    from exubio.io.results import write_json

    files = sorted(p.name for p in folder.iterdir())
    write_json(folder / DONE_FILE, {"outcome": out.row(), "files": files,
                                    "note": "written last: this folder's result set is complete"})


# --------------------------------------------------------------------------------------------
# The study
# --------------------------------------------------------------------------------------------
def _known(session: Any) -> Any:
    """The session with what its bindings hold computed once here (exubio.trust.assess.known_before_trials):
    its trials' jobs carry them to the workers."""
    from exubio.trust.assess import known_before_trials

    known_before_trials(session.binding, expect=session.generic_binding)
    return session


def _calibrate_session(s: SessionSpec, folder: Path, signs: str | None = None) -> tuple[Any, Any, str]:
    """(session, calibration, error) of a session: its model and protocol loaded once and, with a
    static trial, calibrated (exubio.run.session.SessionCalibration, its model file in
    ``folder/calibration``)."""
    from exubio.run.inputs import load_session
    from exubio.run.session import StaticSpec, calibrate_session

    tmp = folder / f"{_TMP_PREFIX}calibration-{os.getpid()}"
    try:
        session = load_session(model_path=s.model, protocol_path=s.protocol, body_mass_kg=s.body_mass_kg, signs=signs)
        if s.static is None:
            return _known(session), None, ""
        cal_dir = folder / "calibration"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        from exubio.io.trial import read_trial

        static = read_trial(s.static)
        static_relabel = s.relabel if s.static_relabel is None else s.static_relabel
        if static_relabel:
            from exubio.protocol.labels import relabel_trajectories

            static = relabel_trajectories(static, static_relabel, option=f"{s.subject}/{s.session} relabel")
        cal = calibrate_session(static, session, tmp, s.static.stem, overwrite=True,
                                spec=StaticSpec(functional=s.functional, scapula_trials=tuple(s.scapula_trials)))
        from exubio.io.results import write_json

        write_json(tmp / DONE_FILE, {"static": str(s.static), "model": cal.model_file.name})
        if cal_dir.exists():
            shutil.rmtree(cal_dir)
        tmp.rename(cal_dir)
        cal = cal.moved_to(cal_dir / cal.model_file.name)
        _known(cal.session)
        return session, cal, ""
    except Exception as exc:  # noqa: BLE001 - the session's trials are reported failed with the reason
        shutil.rmtree(tmp, ignore_errors=True)
        if s.static is None:
            return None, None, str(exc)
        return None, None, f"calibration on {s.static.name} failed: {exc}"


def _same_signs(folder: Path, signs: str | None) -> None:
    """A complete trial of an earlier run is kept only when its angles are in the convention this
    run asks for (``signs``; None: whatever its protocol said): else InputError naming it."""
    if signs is None:
        return
    for summary in sorted(folder.glob("*" + SUFFIXES["summary"])):
        try:
            had = json.loads(summary.read_text(encoding="utf-8")).get("signs", "isb")
        except (OSError, ValueError):
            continue
        if had != signs:
            raise InputError(f"{summary}: this trial's angles were written with signs {had}, this run asks for {signs} "
                             f"(signs key or --signs); run the study into another --out folder")


def plan(spec: StudySpec, out_dir: Path) -> tuple[list[TrialTask], list[TrialOutcome]]:
    """The trials to run and the ones already complete (skipped); sessions are calibrated here."""
    tasks, skipped = [], []
    for s in spec.sessions:
        folder = out_dir / s.subject / s.session
        trial_dirs = {t: folder / t.stem for t in s.trials}
        pending = [t for t in s.trials if not (trial_dirs[t] / DONE_FILE).is_file()
                   or not moments_as_asked(trial_dirs[t], t.stem, s.methods, s.body_mass_kg, s.hand_load_kg)]
        for t in s.trials:
            if t not in pending:
                _same_signs(trial_dirs[t], spec.signs)
                done = json.loads((trial_dirs[t] / DONE_FILE).read_text(encoding="utf-8")).get("outcome", {})
                o = TrialOutcome(s.subject, s.session, str(t), str(trial_dirs[t]), "skipped (complete)",
                                 verdicts={m: done.get(f"{m}_verdict") for m in method_names() if done.get(f"{m}_verdict")},
                                 frames=done.get("frames"), wall_s=done.get("wall_s"),
                                 pf_ls_max_rmse_deg=done.get("pf_ls_max_rmse_deg"), reasons=done.get("reasons") or "",
                                 residual_mm={m: done.get(f"{m}_residual_mm") for m in method_names()
                                              if done.get(f"{m}_residual_mm") is not None})
                skipped.append(o)
        if not pending:
            continue
        folder.mkdir(parents=True, exist_ok=True)
        session, cal, err = _calibrate_session(s, folder, spec.signs)
        for t in pending:
            if err:
                skipped.append(TrialOutcome(s.subject, s.session, str(t), str(trial_dirs[t]), "failed", error=err))
                continue
            from exubio.run.job import TrialJob

            scale = session.protocol.pf_inertia_scale  # the protocol's defaults.pf_inertia_scale
            job = TrialJob(t, trial_dirs[t], methods=s.methods, session=session, static_frames=s.static_frames,
                           report=spec.report, calibration=cal, relabel=s.relabel_of(t) or {},
                           options={"pf": {"inertia_scale": scale}} if scale is not None and "pf" in s.methods else {},
                           hand_load_kg=s.hand_load_kg)
            tasks.append(TrialTask(subject=s.subject, session=s.session, trial=str(t), final_dir=str(trial_dirs[t]),
                                   job=job))
    return tasks, skipped


def _failed(t: TrialTask, exc: BaseException) -> TrialOutcome:
    """The outcome of a trial whose worker died (e.g. out of memory)."""
    return TrialOutcome(t.subject, t.session, t.trial, t.final_dir, "failed", error=f"{type(exc).__name__}: {exc}")


def write_table(out_dir: Path, spec: StudySpec, outcomes: Iterable[TrialOutcome]) -> tuple[Path, Path]:
    """study.csv and study.json (atomic), one row per trial in study order."""
    from exubio.io.results import atomic_write, write_json

    order = {(s.subject, s.session, str(t)): k for k, (s, t) in
             enumerate((s, t) for s in spec.sessions for t in s.trials)}
    rows = [o.row() for o in sorted(outcomes, key=lambda o: order.get((o.subject, o.session, o.trial), 1 << 30))]
    buf = io.StringIO()
    columns = study_columns()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in columns})
    csv_path = atomic_write(out_dir / "study.csv", lambda tmp: tmp.write_text(buf.getvalue(), encoding="utf-8"))
    json_path = write_json(out_dir / "study.json", {
        "study": spec.name, "source": str(spec.source), "trials": rows,
        "counts": {st: sum(r["status"] == st for r in rows) for st in ("done", "skipped (complete)", "failed")},
        "units": {"residual": "mm", "agreement": "deg", "wall": "s"}})
    return csv_path, json_path


def _duration(seconds: float) -> str:
    """A time left as a person reads it: 45 s, 3 min, 1 h 20 min."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 90 else f"{minutes // 60} h {minutes % 60:02d} min"


def run_study(spec: StudySpec, out_dir: str | Path, /, *, jobs: int = 1, scheduler: str | None = None,
              progress: Callable[[str], None] | None = None) -> list[TrialOutcome]:
    """Run (or resume) a study into out_dir; returns every trial's outcome, writes the study table
    and report. ``jobs``: local processes; ``scheduler``: Dask ("local:N" or "tcp://HOST:PORT")."""
    say = progress or (lambda m: log.info("%s", m))
    if jobs < 1:
        raise InputError(f"--jobs {jobs}: expected a whole number of processes >= 1")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if removed := clean_leftovers(out):
        say(f"removed {len(removed)} leftover(s) of an interrupted run")
    tasks, outcomes = plan(spec, out)
    n_total = len(tasks) + len(outcomes)
    say(f"study {spec.name}: {n_total} trial(s), {len(tasks)} to run, "
        f"{sum(o.status.startswith('skipped') for o in outcomes)} complete already")

    started, n_done = time.perf_counter(), 0

    def on_done(o: TrialOutcome) -> None:
        nonlocal n_done
        n_done += 1
        left = len(tasks) - n_done  # the time left: the mean time per finished trial so far (the jobs included)
        eta = f", about {_duration((time.perf_counter() - started) / n_done * left)} left" if left else ""
        say(f"[{n_done}/{len(tasks)}{eta}] {o.subject}/{o.session}/{Path(o.trial).name}: {o.status}"
            + (f" ({', '.join(f'{m} {v}' for m, v in o.verdicts.items())})" if o.verdicts else "")
            + (f": {o.error}" if o.error else ""))

    if tasks:
        try:
            outcomes += run_all(run_trial_task, tasks, jobs=jobs, scheduler=scheduler, on_error=_failed, on_done=on_done)
        except KeyboardInterrupt:
            if scheduler:  # Dask's workers were stopped: their unfinished folders go now, not at the next run
                _remove_after_dask(out)
            raise
    if removed := clean_leftovers(out):  # of a killed run whose workers were still at work when this one began
        say(f"removed {len(removed)} leftover(s) of an interrupted run")
    write_table(out, spec, outcomes)
    trials = study_table.table_trials(spec, outcomes)
    # the long tables are written on a thread while the study report is drawn: their Parquet and CSV
    # writers and the compression run outside Python's lock, so the two share the machine's cores
    with ThreadPoolExecutor(1, thread_name_prefix="exubio-tables") as pool:
        tables = pool.submit(_write_long_tables, out, trials)
        try:
            if spec.report:
                from exubio.report.study_report import build_study_report

                build_study_report(out / "study.json", out / "study.report.pdf")
        finally:
            tables.result()  # its error, if any, is the study's
    return outcomes


def _write_long_tables(out: Path, trials) -> None:
    study_table.write_study_table(out, trials)
    write_moments_table(out, trials)  # sessions with a body mass: moments.parquet

