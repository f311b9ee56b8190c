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
pages; ``angles.parquet`` and ``angles.csv.gz``: every angle in one table (exubio.run.study_table).

Execution: a local process pool (``jobs``), or Dask (``scheduler``: ``"local:N"`` starts a local
cluster of N workers, ``"tcp://HOST:PORT"`` uses a running scheduler). Workers are long-lived
processes that import exubio once. A trial's exception never stops the study.
"""
from __future__ import annotations

import dataclasses
import csv
import glob
import io
import json
import logging
import os
import shutil
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Mapping

from exubio.io.resources import shipped_beside
from exubio.io.yaml import read_yaml
from exubio.errors import ExubioError, InputError
from exubio.run import interrupt, study_table
from exubio.run.executors import run_all
from exubio.run.study_leftovers import _TMP_PREFIX, _remove_after_dask, clean_leftovers

if TYPE_CHECKING:
    from exubio.run.job import TrialResult

log = logging.getLogger(__name__)

__all__ = ["StudySpec", "SessionSpec", "TrialTask", "TrialOutcome", "load_study", "run_study", "DONE_FILE",
           "STUDY_COLUMNS"]

DONE_FILE = "DONE.json"
_STUDY_KEYS = {"schema_version", "name", "methods", "report", "sessions", "signs"}
_SESSION_KEYS = {"subject", "session", "protocol", "model", "static", "functional", "scapula_trial", "static_frames",
                 "trials", "methods", "relabel", "static_relabel", "trial_relabel", "tasks"}
STUDY_COLUMNS = ("subject", "session", "trial", "status", "pf_verdict", "ls_verdict", "frames", "pf_residual_mm",
                 "ls_residual_mm", "pf_ls_max_rmse_deg", "wall_s", "folder", "error", "reasons")


@dataclass(frozen=True)
class SessionSpec:
    subject: str
    session: str
    trials: tuple[Path, ...]
    protocol: Path | None = None
    model: Path | None = None
    static: Path | None = None
    functional: Path | None = None
    static_frames: str | None = None
    scapula_trials: tuple[Path, ...] = ()
    methods: tuple[str, ...] = ("pf", "ls")
    relabel: Mapping[str, str] = field(default_factory=dict)  # every trial and the static
    static_relabel: Mapping[str, str] | None = None  # the static only (None: relabel)
    trial_relabel: Mapping[str, Mapping[str, str]] = field(default_factory=dict)  # trial file name -> its own
    tasks: Mapping[str, str] = field(default_factory=dict)  # trial file name -> its task (default: its stem)

    def relabel_of(self, trial: Path) -> dict[str, str]:
        return dict(self.trial_relabel.get(trial.name, self.relabel))


@dataclass(frozen=True)
class StudySpec:
    name: str
    source: Path
    sessions: tuple[SessionSpec, ...]
    report: bool = True
    signs: str | None = None  # the angles' sign convention of every trial (exubio.model.signs); None: each protocol's


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
        return {"subject": self.subject, "session": self.session, "trial": Path(self.trial).name,
                "status": self.status, "pf_verdict": self.verdicts.get("pf", ""),
                "ls_verdict": self.verdicts.get("ls", ""), "frames": self.frames,
                "pf_residual_mm": self.residual_mm.get("pf"), "ls_residual_mm": self.residual_mm.get("ls"),
                "pf_ls_max_rmse_deg": self.pf_ls_max_rmse_deg, "wall_s": self.wall_s, "folder": self.folder,
                "error": self.error, "reasons": self.reasons}


# --------------------------------------------------------------------------------------------
# The study file
# --------------------------------------------------------------------------------------------
def _path(value: Any, base: Path, where: str) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise InputError(f"{where}: expected a file path, got {value!r}")
    p = (base / value) if not Path(value).is_absolute() else Path(value)
    if not p.exists():
        raise InputError(f"{where}: {p} does not exist")
    return p


def _methods(value: Any, where: str) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not value or any(m not in ("pf", "ls") for m in value):
        raise InputError(f"{where}: methods must be a list of 'pf' and/or 'ls', got {value!r}")
    return tuple(dict.fromkeys(value))


def _relabel_map(value: Any, where: str) -> dict[str, str] | None:
    """A relabel mapping of a study file ({trial label: read as}); InputError naming the key."""
    if value is None:
        return None
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) and k and v
                                              for k, v in value.items()):
        raise InputError(f"{where}: expected a mapping of trial label -> the label it is read as, e.g. "
                         f"{{RADIUS: ULNA, ULNA: RADIUS}}; got {value!r}")
    return dict(value)


def load_study(path: str | Path, /, *, signs: str | None = None) -> StudySpec:
    """Read and check a study file: every key, path and glob, before any work (InputError naming
    the file and the key). ``signs`` (--signs): the angles' sign convention over the file's
    ``signs`` key (which is over each session's protocol's)."""
    path = Path(path)
    data = read_yaml(path, error=InputError)
    src = str(path)
    if not isinstance(data, dict):
        raise InputError(f"{src}: a study file is a mapping with 'sessions'")
    unknown = set(data) - _STUDY_KEYS
    if unknown:
        raise InputError(f"{src}: unknown key(s) {sorted(unknown)}; expected {sorted(_STUDY_KEYS)}")
    if data.get("schema_version") != 1:
        raise InputError(f"{src}: schema_version: expected 1, got {data.get('schema_version')!r}")
    methods = _methods(data.get("methods", ["pf", "ls"]), f"{src}: methods")
    report = data.get("report", True)
    if not isinstance(report, bool):
        raise InputError(f"{src}: report: expected true or false, got {report!r}")
    if signs is None and data.get("signs") is not None:
        from exubio.model.signs import check_signs

        signs = check_signs(data["signs"], f"{src}: signs")
    raw = data.get("sessions")
    if not isinstance(raw, list) or not raw:
        raise InputError(f"{src}: sessions: expected a non-empty list of sessions")
    base = path.parent
    sessions, seen, subjects = [], set(), []
    for k, s in enumerate(raw):
        where = f"{src}: sessions[{k}]"
        if not isinstance(s, dict):
            raise InputError(f"{where}: expected a mapping with subject and trials")
        unknown = set(s) - _SESSION_KEYS
        if unknown:
            raise InputError(f"{where}: unknown key(s) {sorted(unknown)}; expected {sorted(_SESSION_KEYS)}")
        subject = s.get("subject")
        if not isinstance(subject, str) or not subject or "/" in subject or subject.startswith("."):
            raise InputError(f"{where}.subject: expected a name (no '/', not starting with '.'), got {subject!r}")
        session = str(s.get("session", f"s{sum(x == subject for x in subjects) + 1}"))  # counted per subject
        subjects.append(subject)
        if "/" in session or session.startswith(".") or not session:
            raise InputError(f"{where}.session: expected a name (no '/', not starting with '.'), got {session!r}")
        if (subject, session) in seen:
            raise InputError(f"{where}: subject {subject} session {session} appears twice; name the sessions")
        seen.add((subject, session))
        globs = s.get("trials")
        if isinstance(globs, str):
            globs = [globs]
        if not isinstance(globs, list) or not globs:
            raise InputError(f"{where}.trials: expected a list of file patterns, got {globs!r}")
        trials: list[Path] = []
        for g in globs:
            hits = sorted(glob.glob(str(base / g)) if not Path(g).is_absolute() else glob.glob(g))
            if not hits:
                raise InputError(f"{where}.trials: '{g}' matches no file (relative to {base})")
            trials += [Path(h) for h in hits if Path(h) not in trials]
        stems = [t.stem for t in trials]
        dup = sorted({x for x in stems if stems.count(x) > 1})
        if dup:
            raise InputError(f"{where}.trials: several trials named {dup} in one session; their results would share a "
                             f"folder: split them into sessions")
        static = _path(s.get("static"), base, f"{where}.static")
        functional = _path(s.get("functional"), base, f"{where}.functional")
        if functional is not None and static is None:
            raise InputError(f"{where}.functional: a functional trial refines a calibration on a static trial; give "
                             f"static as well")
        raw = s.get("scapula_trial")
        raw = [] if raw is None else (raw if isinstance(raw, list) else [raw])
        scapula_trials = tuple(_path(v, base, f"{where}.scapula_trial") for v in raw)
        if scapula_trials and static is None:
            raise InputError(f"{where}.scapula_trial: a scapula movement trial refines a calibration on a static trial; "
                             f"give static as well")
        frames = s.get("static_frames")
        if frames is not None and static is not None:
            raise InputError(f"{where}.static_frames: with a static trial the window is found in it; give one of the two")
        relabel = _relabel_map(s.get("relabel"), f"{where}.relabel") or {}
        static_relabel = _relabel_map(s.get("static_relabel"), f"{where}.static_relabel")
        if static_relabel is not None and static is None:
            raise InputError(f"{where}.static_relabel: relabels the static trial; the session has no static")
        per_trial = s.get("trial_relabel") or {}
        if not isinstance(per_trial, dict):
            raise InputError(f"{where}.trial_relabel: expected a mapping of trial file name -> {{label: read as}}")
        names = {t.name for t in trials}
        trial_relabel = {}
        for name, mapping in per_trial.items():
            if str(name) not in names:
                raise InputError(f"{where}.trial_relabel.{name}: not a trial of this session; its trials are {sorted(names)}")
            trial_relabel[str(name)] = _relabel_map(mapping, f"{where}.trial_relabel.{name}") or {}
        sessions.append(SessionSpec(
            subject=subject, session=session, trials=tuple(trials), relabel=relabel, static_relabel=static_relabel,
            trial_relabel=trial_relabel, tasks=study_table.tasks_key(s.get("tasks"), names, f"{where}.tasks"),
            protocol=_path(shipped_beside(s.get("protocol"), base, "exubio.protocols", "protocols", "upper_limb_21.yaml"),
                           base, f"{where}.protocol"),
            model=_path(shipped_beside(s.get("model"), base, "exubio.models", "models", "upper_extremity.yaml"),
                        base, f"{where}.model"), static=static, functional=functional,
            static_frames=None if frames is None else str(frames), scapula_trials=scapula_trials,
            methods=_methods(s["methods"], f"{where}.methods") if "methods" in s else methods))
    return StudySpec(name=str(data.get("name", path.stem)), source=path, sessions=tuple(sessions), report=report,
                     signs=signs)


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
def _calibrate_session(s: SessionSpec, folder: Path, signs: str | None = None) -> tuple[Any, Any, str]:
    """(session, calibration, error) of a session: its model and protocol loaded once and, with a
    static trial, calibrated (exubio.run.session.SessionCalibration, its model file in
    ``folder/calibration``)."""
    from exubio.run.inputs import load_session
    from exubio.run.session import StaticSpec, calibrate_session

    tmp = folder / f"{_TMP_PREFIX}calibration-{os.getpid()}"
    try:
        session = load_session(model_path=s.model, protocol_path=s.protocol, signs=signs)
        if s.static is None:
            return session, None, ""
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
        return session, cal.moved_to(cal_dir / cal.model_file.name), ""
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
    for summary in sorted(folder.glob("*.summary.json")):
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
        pending = [t for t in s.trials if not (trial_dirs[t] / DONE_FILE).is_file()]
        for t in s.trials:
            if t not in pending:
                _same_signs(trial_dirs[t], spec.signs)
                done = json.loads((trial_dirs[t] / DONE_FILE).read_text(encoding="utf-8")).get("outcome", {})
                o = TrialOutcome(s.subject, s.session, str(t), str(trial_dirs[t]), "skipped (complete)",
                                 verdicts={m: done.get(f"{m}_verdict") for m in ("pf", "ls") if done.get(f"{m}_verdict")},
                                 frames=done.get("frames"), wall_s=done.get("wall_s"),
                                 pf_ls_max_rmse_deg=done.get("pf_ls_max_rmse_deg"), reasons=done.get("reasons") or "",
                                 residual_mm={m: done.get(f"{m}_residual_mm") for m in ("pf", "ls")
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

            job = TrialJob(t, trial_dirs[t], methods=s.methods, session=session, static_frames=s.static_frames,
                           report=spec.report, calibration=cal, relabel=s.relabel_of(t) or {})
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
    w = csv.DictWriter(buf, fieldnames=STUDY_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r[k] is None else r[k]) for k in STUDY_COLUMNS})
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
    study_table.write_study_table(out, study_table.table_trials(spec, outcomes))
    if spec.report:
        from exubio.report.study_report import build_study_report

        build_study_report(out / "study.json", out / "study.report.pdf")
    return outcomes

