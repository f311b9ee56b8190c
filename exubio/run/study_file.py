"""A study file (YAML): its sessions (subject, protocol, model, static, functional and scapula
trials, static frames, trials by glob, relabellings, tasks, body mass) read and checked, every key,
path and glob, before any work (InputError naming the file and the key). ``exubio study
--template`` prints one with every key explained (exubio.run.study_template); exubio.run.study runs it."""
from __future__ import annotations

import glob
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from exubio.errors import InputError
from exubio.io.resources import shipped_beside
from exubio.io.yaml import read_yaml
from exubio.method_registry import method_names
from exubio.run import study_table
from exubio.run.study_moments import SESSION_KEYS, session_moments

__all__ = ["SessionSpec", "StudySpec", "load_study"]

_STUDY_KEYS = {"schema_version", "name", "methods", "report", "sessions", "signs"}
_SESSION_KEYS = {"subject", "session", "protocol", "model", "static", "functional", "scapula_trial", "static_frames",
                 "trials", "methods", "relabel", "static_relabel", "trial_relabel", "tasks", *SESSION_KEYS}




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
    body_mass_kg: float | None = None  # with it, the joint moments (exubio.run.study_moments)
    hand_load_kg: float | None = None  # the mass in the hand of the joint moments; None: no moments

    def relabel_of(self, trial: Path) -> dict[str, str]:
        return dict(self.trial_relabel.get(trial.name, self.relabel))


@dataclass(frozen=True)
class StudySpec:
    name: str
    source: Path
    sessions: tuple[SessionSpec, ...]
    report: bool = True
    signs: str | None = None  # the angles' sign convention of every trial (exubio.model.signs); None: each protocol's


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
    if not isinstance(value, list) or not value or any(m not in method_names() for m in value):
        raise InputError(f"{where}: methods must be a list of {' and/or '.join(map(repr, method_names()))}, "
                         f"got {value!r}")
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


def load_study(path: str | Path, /, *, body_mass_kg: float | None = None, signs: str | None = None) -> StudySpec:
    """Read and check a study file: every key, path and glob, before any work (InputError naming
    the file and the key); ``body_mass_kg`` (``--body-mass``): the joint moments of every session
    that gives no body_mass_kg of its own (exubio.run.study_moments). ``signs`` (--signs): the
    angles' sign convention over the file's ``signs`` key (which is over each session's protocol's)."""
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
        mass, load = session_moments(s, where, default_mass_kg=body_mass_kg)
        sessions.append(SessionSpec(body_mass_kg=mass, hand_load_kg=load,
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
