"""Same outputs before and after a change: run the same exubio command lines with a base commit
and with a checkout under test, and compare the files they write.

The base commit is checked out in a temporary git worktree (``git worktree add --detach``); each
checkout is run as ``sys.executable -m exubio.cli ...`` in a subprocess with PYTHONPATH set to it
and the working folder outside both checkouts, so this script never imports exubio and works
whatever the package layout. A first ``python -c`` in the same environment checks that exubio (and
its shipped models, protocols and data) come from the intended checkout; an editable install of
exubio in the venv is switched off in the subprocesses (its import hook would otherwise resolve
``exubio.models`` and any module missing from the checkout to the editable copy).

Sets of command lines (``--set``):
  demo        ``exubio demo``
  study       9 trials written by ``exubio simulate`` (2 subjects: one calibrated on a simulated
              static trial, one on its trials' first frames; model perturbations, soft-tissue
              artefact, a RADIUS/ULNA swap read through ``trial_relabel``), run by ``exubio study
              --jobs 2``; then ``exubio export-model`` of the calibrated model (.osim, .bioMod)
  real        every real trial of ../shared/data (SOURCES.md) with ``--method both``: the
              kinova_martin task trials with their session's static (shipped protocol, and the
              session's relabelling protocol protocols/examples/kinova_martin_session.yaml),
              martin_dynamique with martin_statique, F0_boire_05 on its first 20 frames, the two
              TRC trials with thoracoscapular_9 on their first 50 frames (as
              studies/trust_real_trials.py runs them); then export-model of two calibrated models
  real-quick  martin_dynamique with martin_statique only
  study100    a study of 100 trials written by ``exubio simulate`` (10 subjects x 10 trials of 4 s at
              100 Hz, the four motions, 1 mm noise, 5 mm soft-tissue artefact; odd subjects calibrated
              on their trials' first frames), both methods, reports on, ``exubio study --jobs 2``

Comparison of the two output trees: the same set of files and the same exit code for every
command; text files (CSV, .mot, .json, YAML, .osim, .bioMod, .trc, ...) byte for byte once the
absolute paths of the checkout, the run folder and the data folder are replaced by placeholders and
the values of the timing fields listed in IGNORED_* below are blanked; .npz files array by array
(names, dtype, shape, values by np.array_equal with equal_nan; strings with the same path
placeholders; the JSON strings with the same blanked keys), timing arrays excepted; C3D and other
binary files byte for byte; .gz files by the bytes they hold (the compression is not compared); PNG pixel for pixel (Pillow); PDF by page count only (see
PDF_REASON). ``--no-ignore`` compares without blanking anything (to see what varies run to run:
``--base X --head X`` runs one commit twice).

Usage:
    python benchmarks/same_outputs.py --base 336130f                       # head: this checkout
    python benchmarks/same_outputs.py --base 336130f --head ../wt --set demo,study,real --keep /tmp/same_base
    python benchmarks/same_outputs.py --base-outputs /tmp/same_base --head ../wt   # reuse a kept base run
    python benchmarks/same_outputs.py --base 336130f --head 336130f --no-ignore   # run-to-run variation

Exit codes: 0 identical apart from the ignored fields; 1 some file or exit code differs; 2 the
comparison could not be made (base commit absent, a checkout that does not import, a base command
that exits with 2 or more, a set missing from --base-outputs).
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "data"
ALL_SETS = ("demo", "study", "real", "real-quick", "study100")
DEFAULT_SETS = "demo,study,real"
MANIFEST = "manifest.json"

# ---------------------------------------------------------------------------------------------
# What is not compared, and why. Every entry was seen to vary between two runs of the same commit
# (python benchmarks/same_outputs.py --base 336130f --head 336130f --no-ignore); nothing else does.

# JSON keys, wherever they are nested (summary.json files, study.json, and the JSON strings of the
# .npz files); the value is replaced by "<ignored>", the key itself must still be there.
IGNORED_KEYS = {
    "wall_time_s": "wall-clock seconds of a reconstruction (summary.json)",
    "ms_per_frame": "wall-clock milliseconds per frame (summary.json)",
    "timings_s": "wall-clock seconds per phase of a reconstruction: equilibrium, build, integration, "
                 "recovery, residuals, total (summary.json)",
    "exudyn_cpu_times_s": "Exudyn's CPU-time breakdown of the PF solve (summary.json, info_json of the PF .npz)",
    "wall_s": "wall-clock seconds of a study trial (study.json)",
    "inputs_sha256": "the fingerprint of a run's inputs (exubio.run.resume): it hashes the calibrated model's "
                     "file, whose text names the checkout's absolute paths (the base worktree's and the head's), "
                     "and exubio's code (code_fingerprint), which any two commits differ in; blanked in the "
                     "calibrated model's YAML too (its calibration section)",
}
_YAML_IGNORED = re.compile(r"^(\s*(?:%s):\s*).*$" % "|".join(re.escape(k) for k in IGNORED_KEYS), re.M)
# .npz arrays the head adds on purpose (issue 37): left out of the head's list of arrays
NEW_NPZ_ARRAYS = {"angle_signs": "issue 37: per angle, the sign the files apply to the ISB angle (all +1 by default)"}
# .npz arrays not compared at all
IGNORED_NPZ_ARRAYS = {
    "timings_json": "the per-phase wall-clock seconds of the reconstruction (the .npz copy of timings_s)",
}
# CSV columns (by header name) whose values are not compared
IGNORED_CSV_COLUMNS = {
    "wall_s": "wall-clock seconds of a study trial (study.csv)",
}
# absolute paths that differ between the two runs by construction; replaced in every text file and
# every string array before the comparison
PATH_PLACEHOLDERS = {
    "<CHECKOUT>": "the checkout being run (models/, protocols/, the shipped example trial are read from it)",
    "<RUN>": "the temporary folder of the run (output folders and the calibrated models' paths)",
    "<DATA>": "the folder of the real trials (../shared/data), the same for both unless a kept base run "
              "was made elsewhere",
}
KNOWN_CHANGES: tuple = ()
"""Changes made on purpose since the base the tests compare with (tests/project/test_same_outputs.py BASE),
each a (side, pattern, replacement, why) undone before the comparison. None since the base moved to
67845a0 (6 December 2026): the girdle's part of every angle's u grows from an offset at rest
(exubio.truth.girdle), which moves every ``*_u_deg`` column and the status where u crosses its bound:
checked before the move (`--base f460097 --set demo,study,real`), no verdict changed, ST internal
rotation is measured in more frames (demo 0.75 -> 0.90, study 0.80 -> 0.97, real trials 0.85 -> 0.87),
every other angle's measured fraction within 0.02, every angle and rate the same (studies/README.md,
"The girdle's error near rest"). Before, it was 320d83e; before that
f053b69 (6 December 2026): gh_abduction and gh_flexion lost their ranges (models/upper_extremity.yaml,
note [13]), which changes every written model file (the two range lines, the exports' ranges written as
one turn), PF's ``limit_active_s`` (no GH limit element), the calibrated models by round-off
(task_flexion_humerus 3e-9 rad), and the one real trial whose static put gh_flexion on its old limit,
martin_dynamique (a palm-down T-pose): its verdicts check -> ok, GH axial rotation moved by up to
9-10 deg, forearm pronation 9 deg, in the T-pose frames (`--base deb7b5f`: every other file of the
demo, the study and the real trials identical, every other verdict the same). Before, the base was
b09a162 with the texts of 6 December 2026 undone (the remedy of an angle not measured for its
uncertainty, the uncertainty's definition line, the unseen mismatch's note and the scapula mismatch's
advice, which no longer send a lab to a scapula trial). Before that, it moved to b09a162 (5 December
2026, issue 33): a segment the model does not follow turns its frame in the angles' uncertainty
(exubio.trust.angle_uncertainty.misfit_angle_variance), which moves u, and the status where u passes
its bound, on trials whose model misfits; the demo changed only in the uncertainty's definition line,
and no real trial's verdict changed (studies/README.md, "A misfit turns its segment's frame"). Before,
it moved to 30ce9ee (5 December 2026), after issue 38's compiled kernels (numba: LS's Gauss-Newton
terms and rates, forward kinematics, the decode, the inverse map, the ISB angles) moved every output
by round-off, checked before the move (`--base da435a6`): demo, q 2.3e-9 rad (PF) and 8.8e-10 (LS),
q-dot 1.3e-8 rad/s, q-ddot 1.1e-7 rad/s^2, model points and residuals 3e-11 m, the angles' CSV and
.mot in their last printed digit; the study, q 9.3e-9 rad, q-ddot 2.9e-6 rad/s^2, the calibrated
model and its exports 2.8e-9; accuracy against the truth the same to every printed digit
(benchmarks/README.md). The binding and the typed outcome (issue 34) and the memory work (issue
38) were compared with the commits before them: identical (demo and study), and the merge of the
three with the kernels' branch alone: identical. The earlier entries are in this file's history."""
HEAD_BEHAVIOUR: tuple = (
    ("b37a63e", """
def _page_one_every_sample():
    import exubio.report.trial_report as tr
    tr._envelope = lambda t, *ys, **kw: (t, *ys)


_page_one_every_sample()
""", "a trial report's page 1 draws its key angles thinned to their envelope, as page 2 does (issue 38: "
     "tests/report/test_envelope.py holds the drawing within a pixel of every sample's; on a 25-s trial "
     "13,840 of the PNG's 1.17 million pixels differ, by at most 29 of 255 levels, 6 by more than 10 %); "
     "the head draws every sample, as the base does, for its PNG to be compared pixel for pixel"),
)
"""Changes of behaviour since the base, undone in the head's runs (code its sitecustomize runs
before the command), each (the commit that made the change, code, why): undone only where the base
predates that commit (a base that has it draws as the head does)."""
PDF_REASON = ("PDF reports print wall times and ms per frame (trial report, study table), and matplotlib "
              "writes the creation date: their bytes differ run to run. Compared: the page count. The "
              "numbers they plot are the CSV/NPZ files compared exactly, and a trial report's first page "
              "is also its PNG, compared pixel for pixel.")
TEXT_SUFFIXES = {".csv", ".mot", ".json", ".yaml", ".yml", ".osim", ".biomod", ".trc", ".txt", ".md", ".html",
                 ".sto", ".xml", ".log"}

# ---------------------------------------------------------------------------------------------
# The command lines. Placeholders: {out} the set's output folder, {checkout} the checkout being run,
# {data} the real data folder. A step is a command line, or a file the script writes (an input).


@dataclass(frozen=True)
class Step:
    name: str
    argv: tuple[str, ...] = ()
    write: tuple[str, str] | None = None  # (relative path, text): an input file, identical for both


STUDY_YAML = """\
schema_version: 1
name: same-outputs study
methods: [pf, ls]
sessions:
  - subject: S01
    session: day1
    static: trials/S01/static.c3d
    trials: ["trials/S01/task_*.c3d"]
  - subject: S02
    session: day1
    static_frames: "0:30"
    trials: ["trials/S02/task_*.c3d"]
    trial_relabel:
      task_swapped.c3d: {RADIUS: ULNA, ULNA: RADIUS}
"""

_SIMULATED = (  # (path under trials/, simulate arguments)
    ("S01/static.c3d", "--motion abduction --duration 2 --noise-mm 0.5 --seed 10"),
    ("S01/task_abduction.c3d", "--motion abduction --duration 4 --noise-mm 1 --sta-mm 5 --seed 11"),
    ("S01/task_flexion.c3d", "--motion flexion --duration 4 --noise-mm 1 --sta-mm 5 --seed 12"),
    ("S01/task_scaption.c3d", "--motion scaption --duration 4 --noise-mm 0.5 --seed 13"),
    ("S01/task_sier.c3d", "--motion sier --duration 4 --noise-mm 1 --seed 14"),
    ("S02/task_abduction_ellipsoid.c3d", "--motion abduction --duration 4 --noise-mm 1 --seed 21 "
                                         "--perturb ellipsoid_centre_mm=0,8,0"),
    ("S02/task_flexion_humerus.c3d", "--motion flexion --duration 4 --noise-mm 1 --seed 22 --perturb length.humerus=1.08"),
    ("S02/task_swapped.c3d", "--motion scaption --duration 4 --noise-mm 1 --seed 23"),
    ("S02/task_fast.c3d", "--motion abduction --duration 3 --rate 200 --noise-mm 2 --sta-mm 10 --seed 24"),
)


def _c3d(name: str) -> str:
    return f"{{data}}/c3d/bioptim_exo_{name}.c3d"


_KINOVA = tuple(_c3d(f"kinova_martin_{t}_f3_1") for t in ("aisselle", "dent", "manger", "tete"))
_MARTIN = Step("martin_dynamique", ("reconstruct", _c3d("martin_dynamique"), "--static", _c3d("martin_statique"),
                                    "--method", "both", "--out", "{out}/martin"))
_EXPORT_MARTIN = "{out}/martin/bioptim_exo_martin_statique.model.yaml"


def steps(set_name: str) -> list[Step]:
    if set_name == "demo":
        return [Step("demo", ("demo", "--out", "{out}/demo"))]
    if set_name == "study":
        out = [Step(f"simulate {p}", ("simulate", *a.split(), "--out", f"{{out}}/trials/{p}")) for p, a in _SIMULATED]
        out.append(Step("study.yaml", write=("study.yaml", STUDY_YAML)))
        out.append(Step("study", ("study", "{out}/study.yaml", "--out", "{out}/results", "--jobs", "2")))
        model = "{out}/results/S01/day1/calibration/static.model.yaml"
        out += [Step("export osim", ("export-model", model, "--format", "osim", "--out", "{out}/export/S01.osim")),
                Step("export biomod", ("export-model", model, "--format", "biomod", "--out", "{out}/export/S01.bioMod"))]
        return out
    if set_name == "real-quick":
        return [_MARTIN]
    if set_name == "study100":
        motions = ("abduction", "flexion", "scaption", "sier")
        out = [Step(f"simulate S{s:02d}/t{t}", ("simulate", "--motion", motions[(s + t) % 4], "--duration", "4",
                                                "--rate", "100", "--noise-mm", "1", "--sta-mm", "5",
                                                "--seed", str(100 * s + t), "--out", f"{{out}}/trials/S{s:02d}/t{t}.c3d"))
               for s in range(10) for t in range(10)]
        sessions = "".join(f"  - subject: S{s:02d}\n    trials: [\"trials/S{s:02d}/t*.c3d\"]\n"
                           + ('    static_frames: "0:30"\n' if s % 2 else "") for s in range(10))
        out.append(Step("study.yaml", write=("study.yaml", f"schema_version: 1\nname: study100\nmethods: [pf, ls]\n"
                                                          f"sessions:\n{sessions}")))
        out.append(Step("study", ("study", "{out}/study.yaml", "--out", "{out}/results", "--jobs", "2")))
        return out
    if set_name == "real":
        static = _c3d("kinova_martin_statique")
        return [
            Step("kinova_martin, shipped protocol", ("reconstruct", *_KINOVA, "--static", static, "--method", "both",
                                                     "--jobs", "2", "--out", "{out}/kinova_martin_shipped")),
            Step("kinova_martin, session protocol", ("reconstruct", *_KINOVA, "--static", static, "--method", "both",
                                                     "--protocol", "{checkout}/protocols/examples/kinova_martin_session.yaml",
                                                     "--jobs", "2", "--out", "{out}/kinova_martin_session")),
            _MARTIN,
            Step("F0_boire_05", ("reconstruct", _c3d("F0_boire_05"), "--static-frames", "0:20", "--method", "both",
                                 "--out", "{out}/F0_boire")),
            Step("tsm_rmr", ("reconstruct", "{data}/trc/tsm_rmr_ABD01.trc", "{data}/trc/tsm_rmr_FLX01.trc",
                             "--protocol", "thoracoscapular_9", "--static-frames", "0:50", "--method", "both",
                             "--jobs", "2", "--out", "{out}/tsm")),
            Step("export osim", ("export-model", _EXPORT_MARTIN, "--format", "osim", "--out", "{out}/export/martin.osim")),
            Step("export osim model", ("export-model", _EXPORT_MARTIN, "--format", "osim", "--coordinates", "model",
                                       "--out", "{out}/export/martin_model_coordinates.osim")),
            Step("export biomod", ("export-model", _EXPORT_MARTIN, "--format", "biomod", "--out", "{out}/export/martin.bioMod")),
            Step("export tsm osim", ("export-model", "{out}/tsm/tsm_rmr_ABD01.model.yaml", "--format", "osim",
                                     "--out", "{out}/export/tsm_ABD01.osim")),
        ]
    raise ValueError(set_name)


def needs_data(set_name: str) -> bool:
    return set_name in ("real", "real-quick")


# ---------------------------------------------------------------------------------------------
# Running one checkout

# Put first on PYTHONPATH after the checkout: removes the import hooks of an editable install of
# exubio (setuptools' __editable__ finder maps exubio.* to the editable copy whatever PYTHONPATH
# says), then runs the sitecustomize it shadows, if any.
SHIM = '''\
"""Written by benchmarks/same_outputs.py: exubio from PYTHONPATH only, not from an editable install."""
import sys


def _editable(obj):
    mod = str(getattr(obj, "__module__", "") or getattr(type(obj), "__module__", ""))
    return mod.startswith("__editable__") and "exubio" in mod


sys.meta_path[:] = [f for f in sys.meta_path if not _editable(f)]
sys.path_hooks[:] = [h for h in sys.path_hooks if not _editable(h)]
sys.path[:] = [p for p in sys.path if not (p.startswith("__editable__") and "exubio" in p)]
sys.path_importer_cache.clear()


def _chain():
    import importlib.machinery
    import os
    here = os.path.dirname(os.path.abspath(__file__))
    spec = importlib.machinery.PathFinder.find_spec(
        "sitecustomize", [p for p in sys.path if os.path.abspath(p or ".") != here])
    if spec is not None and spec.loader is not None:
        exec(compile(open(spec.origin, encoding="utf-8").read(), spec.origin, "exec"), {"__name__": "sitecustomize"})


_chain()
'''

CHECK = """\
import importlib.metadata as md, importlib.util, json, sys
import exubio
def where(name):
    spec = importlib.util.find_spec(name)
    return None if spec is None else [spec.origin] if spec.origin else list(spec.submodule_search_locations or [])
def version(name):
    try:
        return md.version(name)
    except md.PackageNotFoundError:
        return None
print(json.dumps({
    "exubio": exubio.__file__,
    "shipped": {n: where(n) for n in ("exubio.models", "exubio.protocols", "exubio.data")},
    "editable_hooks": [repr(f) for f in sys.meta_path if "__editable__" in str(getattr(f, "__module__", ""))],
    "python": sys.version.split()[0],
    "versions": {n: version(n) for n in ("numpy", "scipy", "exudyn", "matplotlib", "ezc3d", "PyYAML", "pandas")},
}))
"""


class SetupError(Exception):
    """The comparison cannot be made (exit code 2)."""


def git(repo: Path, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=check)


def resolve_commit(repo: Path, rev: str) -> str | None:
    r = git(repo, "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}", check=False)
    return r.stdout.strip() if r.returncode == 0 else None


def child_env(checkout: Path, shim_dir: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSTARTUP", "PYTHONHOME")}
    env["PYTHONPATH"] = os.pathsep.join([str(checkout), str(shim_dir)])
    # the same for both runs: one BLAS/OpenMP thread (sums in one order), no display
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
        env[k] = "1"
    env["MPLBACKEND"] = "Agg"
    return env


def check_checkout(checkout: Path, env: dict, cwd: Path) -> dict:
    r = subprocess.run([sys.executable, "-c", CHECK], env=env, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SetupError(f"exubio does not import from {checkout}:\n{r.stderr.strip()}")
    info = json.loads(r.stdout.strip().splitlines()[-1])
    root = checkout.resolve()
    places = [info["exubio"]] + [p for v in info["shipped"].values() for p in (v or [])]
    outside = [p for p in places if not Path(p).resolve().is_relative_to(root)]
    if outside or info["editable_hooks"]:
        raise SetupError(f"exubio is not (only) from {checkout}: {outside or info['editable_hooks']}")
    return info


def fill(arg: str, out: Path, checkout: Path, data: Path) -> str:
    return arg.replace("{out}", str(out)).replace("{checkout}", str(checkout)).replace("{data}", str(data))


def undone_for(repo: Path, base_commit: str | None) -> list[tuple]:
    """The HEAD_BEHAVIOUR entries a base needs undone: those whose commit the base does not contain
    (all of them when the base's commit is not known)."""
    return [e for e in HEAD_BEHAVIOUR if base_commit is None
            or git(repo, "merge-base", "--is-ancestor", e[0], base_commit, check=False).returncode != 0]


def run_side(label: str, checkout: Path, run_root: Path, sets: list[str], data: Path, commit: str | None,
             undo_entries: list[tuple] = ()) -> dict:
    """Run every step of the sets with one checkout; the outputs in run_root/outputs/<set>/, the
    logs in run_root/logs/<set>/, what was run in run_root/manifest.json."""
    shim = run_root / "shim"
    shim.mkdir(parents=True, exist_ok=True)
    undo = "".join(code for _, code, _ in undo_entries) if label == "head" else ""
    (shim / "sitecustomize.py").write_text(SHIM + undo, encoding="utf-8")
    cwd = run_root / "cwd"
    cwd.mkdir(exist_ok=True)
    env = child_env(checkout, shim)
    info = check_checkout(checkout, env, cwd)
    print(f"[{label}] exubio from {info['exubio']} (python {info['python']})", file=sys.stderr, flush=True)
    manifest = {"label": label, "commit": commit, "checkout": str(checkout), "run_root": str(run_root),
                "data": str(data), "check": info, "sets": {}}
    (run_root / MANIFEST).write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    for s in sets:
        out = run_root / "outputs" / s
        logs = run_root / "logs" / s
        out.mkdir(parents=True)
        logs.mkdir(parents=True)
        t_set = time.perf_counter()
        records = []
        for i, st in enumerate(steps(s)):
            if st.write:
                (out / st.write[0]).write_text(st.write[1], encoding="utf-8")
                continue
            argv = [fill(a, out, checkout, data) for a in st.argv]
            if argv[0] in ("simulate", "export-model"):
                Path(argv[argv.index("--out") + 1]).parent.mkdir(parents=True, exist_ok=True)
            t0 = time.perf_counter()
            with open(logs / f"{i:02d}.log", "w", encoding="utf-8") as log:
                log.write("$ exubio " + " ".join(argv) + "\n")
                log.flush()
                rc = subprocess.run([sys.executable, "-m", "exubio.cli", *argv], env=env, cwd=cwd,
                                    stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode
            wall = time.perf_counter() - t0
            records.append({"name": st.name, "argv": list(st.argv), "rc": rc, "wall_s": round(wall, 2),
                            "log": str(logs / f"{i:02d}.log")})
            print(f"[{label}] {s}: {st.name}: exit {rc}, {wall:.1f} s", file=sys.stderr, flush=True)
        manifest["sets"][s] = {"wall_s": round(time.perf_counter() - t_set, 1), "steps": records}
        (run_root / MANIFEST).write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    return manifest


# ---------------------------------------------------------------------------------------------
# Comparing


@dataclass
class Side:
    root: Path  # the folder holding manifest.json, outputs/, logs/
    manifest: dict
    ignore: bool = True
    side: str = "base"

    def mask(self, text: str) -> str:
        if not self.ignore:
            return text
        pairs = []
        for key, ph in (("checkout", "<CHECKOUT>"), ("run_root", "<RUN>"), ("data", "<DATA>")):
            p = self.manifest[key]
            pairs += [(p, ph), (str(Path(p).resolve()), ph)]
        for p, ph in sorted(set(pairs), key=lambda t: -len(t[0])):
            text = text.replace(p, ph)
        for side, pattern, replacement, _ in KNOWN_CHANGES:
            if side == self.side:
                text = re.sub(pattern, replacement, text)
        return text


_DECODER = json.JSONDecoder()


def blank_json(text: str, keys) -> str:
    """The JSON text with the value of every key in ``keys`` (at any depth) replaced by "<ignored>"."""
    keys = list(keys)
    if not keys:
        return text
    pat = re.compile(r'"(?:%s)"\s*:\s*' % "|".join(re.escape(k) for k in keys))
    out, pos = [], 0
    for m in pat.finditer(text):
        if m.start() < pos:
            continue  # inside a value blanked already
        try:
            _, end = _DECODER.raw_decode(text, m.end())
        except ValueError:
            continue
        out += [text[pos:m.end()], '"<ignored>"']
        pos = end
    out.append(text[pos:])
    return "".join(out)


def first_json_difference(a, b, path: str = "") -> str | None:
    if type(a) is not type(b):
        return f"{path or '/'}: {_short(a)} != {_short(b)}"
    if isinstance(a, dict):
        if list(a) != list(b):
            only = [k for k in a if k not in b] + [k for k in b if k not in a]
            return f"{path or '/'}: keys differ ({', '.join(map(str, only[:5])) or 'order'})"
        for k in a:
            d = first_json_difference(a[k], b[k], f"{path}/{k}")
            if d:
                return d
        return None
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path or '/'}: length {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            d = first_json_difference(x, y, f"{path}[{i}]")
            if d:
                return d
        return None
    if a != a and b != b:  # NaN
        return None
    return None if a == b else f"{path or '/'}: {_short(a)} != {_short(b)}"


def _short(x, n: int = 90) -> str:
    s = x if isinstance(x, str) else json.dumps(x) if not isinstance(x, float) else repr(x)
    return s if len(s) <= n else s[: n - 3] + "..."


def first_line_difference(a: str, b: str) -> str:
    la, lb = a.splitlines(), b.splitlines()
    for i, (x, y) in enumerate(zip(la, lb)):
        if x != y:
            return f"line {i + 1}: {_short(x.strip())!r} != {_short(y.strip())!r}"
    if len(la) != len(lb):
        return f"{len(la)} lines != {len(lb)} lines"
    return "line endings or trailing bytes differ"


def compare_text(pa: Path, pb: Path, base: Side, head: Side) -> str | None:
    ta = base.mask(pa.read_text(encoding="utf-8", errors="surrogateescape"))
    tb = head.mask(pb.read_text(encoding="utf-8", errors="surrogateescape"))
    suffix = pa.suffix.lower()
    if suffix == ".json":
        if base.ignore:
            ta, tb = blank_json(ta, IGNORED_KEYS), blank_json(tb, IGNORED_KEYS)
        if ta == tb:
            return None
        try:
            d = first_json_difference(json.loads(ta), json.loads(tb))
        except ValueError:
            d = None
        return d or first_line_difference(ta, tb)
    if suffix in (".yaml", ".yml") and base.ignore:
        ta, tb = _YAML_IGNORED.sub(r"\1<ignored>", ta), _YAML_IGNORED.sub(r"\1<ignored>", tb)
    if suffix == ".csv" and base.ignore:
        header = next(csv.reader(io.StringIO(ta)), [])
        cols = [i for i, h in enumerate(header) if h in IGNORED_CSV_COLUMNS]
        if cols and ta != tb:
            ra, rb = list(csv.reader(io.StringIO(ta))), list(csv.reader(io.StringIO(tb)))
            for r in ra[1:] + rb[1:]:  # the header row stays
                for i in cols:
                    if i < len(r):
                        r[i] = "<ignored>"
            if ra == rb:
                return None
            for n, (x, y) in enumerate(zip(ra, rb)):
                if x != y:
                    j = next((j for j, (u, v) in enumerate(zip(x, y)) if u != v), min(len(x), len(y)))
                    col = header[j] if j < len(header) else f"column {j + 1}"
                    return f"row {n + 1}, {col}: {_short(x[j] if j < len(x) else '')!r} != {_short(y[j] if j < len(y) else '')!r}"
            return f"{len(ra)} rows != {len(rb)} rows"
    return None if ta == tb else first_line_difference(ta, tb)


def compare_npz(pa: Path, pb: Path, base: Side, head: Side) -> str | None:
    with np.load(pa, allow_pickle=False) as za, np.load(pb, allow_pickle=False) as zb:
        files_b = [f for f in zb.files if not (base.ignore and f in NEW_NPZ_ARRAYS and f not in za.files)]
        if za.files != files_b:
            only = sorted(set(za.files) ^ set(files_b))
            return f"arrays differ: {', '.join(only) if only else 'order'}"
        for k in za.files:
            if base.ignore and k in IGNORED_NPZ_ARRAYS:
                continue
            x, y = za[k], zb[k]
            # strings: the width of the dtype follows the longest string (a path, a timing's digits)
            same_type = x.dtype.kind == y.dtype.kind == "U" or x.dtype == y.dtype
            if not same_type or x.shape != y.shape:
                return f"{k}: {x.dtype}{list(x.shape)} != {y.dtype}{list(y.shape)}"
            if x.dtype.kind == "U":
                fa = [base.mask(str(v)) for v in x.ravel()]
                fb = [head.mask(str(v)) for v in y.ravel()]
                if k.endswith("_json") and base.ignore:
                    fa, fb = [blank_json(v, IGNORED_KEYS) for v in fa], [blank_json(v, IGNORED_KEYS) for v in fb]
                for i, (u, v) in enumerate(zip(fa, fb)):
                    if u != v:
                        try:
                            d = first_json_difference(json.loads(u), json.loads(v)) if k.endswith("_json") else None
                        except ValueError:
                            d = None
                        return f"{k}{'' if x.ndim == 0 else f'[{i}]'}: " + (d or f"{_short(u)!r} != {_short(v)!r}")
                continue
            eq = np.equal(x, y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind in "fc" else np.equal(x, y)
            if not np.all(eq):
                idx = tuple(int(i) for i in np.argwhere(~np.asarray(eq))[0])
                extra = ""
                if x.dtype.kind in "fc":
                    with np.errstate(invalid="ignore"):
                        extra = f" (max |diff| {np.nanmax(np.abs(x.astype(float) - y.astype(float))):.3g})"
                return f"{k}{list(idx)}: {x[idx]!r} != {y[idx]!r}{extra}"
    return None


def pdf_pages(p: Path) -> int:
    return len(re.findall(rb"/Type\s*/Page(?![s\w])", p.read_bytes()))


def compare_png(pa: Path, pb: Path) -> str | None:
    from PIL import Image

    with Image.open(pa) as a, Image.open(pb) as b:
        if a.size != b.size or a.mode != b.mode:
            return f"image {a.size} {a.mode} != {b.size} {b.mode}"
        if a.tobytes() != b.tobytes():
            xa, xb = np.asarray(a), np.asarray(b)
            n = int(np.any(xa != xb, axis=-1).sum()) if xa.ndim == 3 else int((xa != xb).sum())
            return f"pixels differ ({n} of {a.size[0] * a.size[1]})"
    return None


def compare_file(rel: str, base: Side, head: Side, set_name: str) -> str | None:
    pa = base.root / "outputs" / set_name / rel
    pb = head.root / "outputs" / set_name / rel
    suffix = pa.suffix.lower()
    if suffix in TEXT_SUFFIXES:
        return compare_text(pa, pb, base, head)
    if suffix == ".npz":
        return compare_npz(pa, pb, base, head)
    if suffix == ".png":
        return compare_png(pa, pb)
    if suffix == ".gz":  # the text inside, byte for byte (the compression level is not an output)
        import gzip

        ta, tb = gzip.decompress(pa.read_bytes()), gzip.decompress(pb.read_bytes())
        return None if ta == tb else first_line_difference(ta.decode("utf-8"), tb.decode("utf-8"))
    if suffix == ".pdf" and base.ignore:
        na, nb = pdf_pages(pa), pdf_pages(pb)
        return None if na == nb else f"{na} pages != {nb} pages"
    ba, bb = pa.read_bytes(), pb.read_bytes()
    if ba == bb:
        return None
    i = next((i for i, (u, v) in enumerate(zip(ba, bb)) if u != v), min(len(ba), len(bb)))
    return f"bytes differ from offset {i} ({len(ba)} and {len(bb)} bytes)"


def files_of(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()} if folder.is_dir() else set()


def compare_set(set_name: str, base: Side, head: Side) -> dict:
    fa = files_of(base.root / "outputs" / set_name)
    fb = files_of(head.root / "outputs" / set_name)
    diffs = {}
    for rel in sorted(fa - fb):
        diffs[rel] = "only in the base run"
    for rel in sorted(fb - fa):
        diffs[rel] = "only in the head run"
    common = sorted(fa & fb)
    for rel in common:
        d = compare_file(rel, base, head, set_name)
        if d:
            diffs[rel] = d
    sa, sb = base.manifest["sets"][set_name]["steps"], head.manifest["sets"][set_name]["steps"]
    for x, y in zip(sa, sb):
        if x["rc"] != y["rc"]:
            diffs[f"exit code of {x['name']}"] = f"{x['rc']} != {y['rc']}"
    if [x["name"] for x in sa] != [y["name"] for y in sb]:
        diffs["command list"] = "the two runs ran different steps"
    return {"set": set_name, "steps": len(sb), "files": len(fa | fb), "compared": len(common),
            "identical": len([r for r in common if r not in diffs]), "diffs": diffs,
            "base_s": base.manifest["sets"][set_name]["wall_s"], "head_s": head.manifest["sets"][set_name]["wall_s"]}


def print_table(rows: list[dict]) -> None:
    head = ("set", "commands", "files", "identical", "differing", "base s", "head s", "first difference")
    lines = []
    for r in rows:
        first = next(iter(r["diffs"].items()), None)
        lines.append((r["set"], str(r["steps"]), str(r["files"]), str(r["identical"]), str(len(r["diffs"])),
                      f"{r['base_s']:.0f}", f"{r['head_s']:.0f}",
                      "-" if first is None else _short(f"{first[0]}: {first[1]}", 100)))
    widths = [max(len(x[i]) for x in [head, *lines]) for i in range(len(head))]
    for x in [head, tuple("-" * w for w in widths), *lines]:
        print("  ".join(c.ljust(w) for c, w in zip(x, widths)).rstrip())
    for r in rows:
        for rel, d in r["diffs"].items():
            print(f"  {r['set']}: {rel}: {d}")


def print_ignored(undone: list[tuple]) -> None:
    print("not compared (values blanked; the keys, columns and arrays must still be there):")
    for title, table in (("JSON key", IGNORED_KEYS), (".npz array", IGNORED_NPZ_ARRAYS),
                         ("CSV column", IGNORED_CSV_COLUMNS), ("path", PATH_PLACEHOLDERS)):
        for k, why in table.items():
            print(textwrap.fill(f"{title} {k}: {why}", 110, initial_indent="  ", subsequent_indent="      "))
    print(textwrap.fill(f"PDF: {PDF_REASON}", 110, initial_indent="  ", subsequent_indent="      "))
    print("undone before the comparison (changes made on purpose):")
    for side, pattern, _, why in KNOWN_CHANGES:
        print(textwrap.fill(f"{side} {pattern}: {why}", 110, initial_indent="  ", subsequent_indent="      "))
    for _, _, why in undone:
        print(textwrap.fill(f"head runs with the old behaviour: {why}", 110, initial_indent="  ",
                            subsequent_indent="      "))


# ---------------------------------------------------------------------------------------------


def load_kept(path: Path) -> tuple[Path, dict]:
    for cand in (path, path / "base"):
        if (cand / MANIFEST).is_file():
            return cand, json.loads((cand / MANIFEST).read_text(encoding="utf-8"))
    raise SetupError(f"no {MANIFEST} in {path} or {path / 'base'}: not a run kept by --keep")


def keep(src: Path, dest: Path) -> None:
    if dest.exists():
        if not (dest / MANIFEST).is_file():
            raise SetupError(f"{dest} exists and is not a kept run: not replaced")
        shutil.rmtree(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copytree(src, dest, ignore=shutil.ignore_patterns("shim", "cwd"))


def add_worktree(repo: Path, commit: str, where: Path) -> Path:
    r = git(repo, "worktree", "add", "--detach", str(where), commit, check=False)
    if r.returncode != 0:
        raise SetupError(f"git worktree add {commit} failed: {r.stderr.strip()}")
    return where


def remove_worktree(repo: Path, where: Path) -> None:
    if git(repo, "worktree", "remove", "--force", str(where), check=False).returncode != 0:
        shutil.rmtree(where, ignore_errors=True)
        git(repo, "worktree", "prune", check=False)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("--base", help="base commit (run in a temporary git worktree); with --base-outputs: "
                                   "checked against the kept run's commit")
    ap.add_argument("--head", default=str(ROOT), help="the checkout under test: a folder (its working tree as "
                                                     "it is) or a commit (a second temporary worktree); default: "
                                                     "the checkout of this script")
    ap.add_argument("--set", default=DEFAULT_SETS, help=f"comma-separated, of {', '.join(ALL_SETS)} "
                                                       f"(default {DEFAULT_SETS})")
    ap.add_argument("--keep", type=Path, help="copy the runs to DIR/base and DIR/head (outputs, logs, manifest)")
    ap.add_argument("--base-outputs", type=Path, help="reuse a base run kept by --keep (DIR or DIR/base) "
                                                     "instead of running the base")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help=f"real data folder (default {DEFAULT_DATA})")
    ap.add_argument("--repo", type=Path, default=ROOT, help="git repository of the commits (default: this checkout's)")
    ap.add_argument("--no-ignore", action="store_true", help="compare everything, timings and paths included")
    args = ap.parse_args(argv)

    sets = [s.strip() for s in args.set.split(",") if s.strip()]
    bad = [s for s in sets if s not in ALL_SETS]
    if bad:
        ap.error(f"unknown set(s) {', '.join(bad)}; known: {', '.join(ALL_SETS)}")
    if not args.base and not args.base_outputs:
        ap.error("give --base COMMIT or --base-outputs DIR")
    data = args.data.resolve()
    skipped = [s for s in sets if needs_data(s) and not (data / "c3d").is_dir()]
    for s in skipped:
        print(f"set {s} skipped: no real data in {data}", file=sys.stderr)
    sets = [s for s in sets if s not in skipped]
    if not sets:
        print("nothing to compare", file=sys.stderr)
        return 0

    for name in ("base", "head"):
        if args.keep and (args.keep / name).exists() and not (args.keep / name / MANIFEST).is_file():
            ap.error(f"{args.keep / name} exists and is not a run kept by --keep: not replaced")
    tmp = Path(tempfile.mkdtemp(prefix="same-outputs-"))
    worktrees: list[Path] = []
    try:
        base_commit = None
        if args.base:
            base_commit = resolve_commit(args.repo, args.base)
            if base_commit is None:
                raise SetupError(f"base commit {args.base} is not in the repository {args.repo} (a shallow clone?)")
        if args.base_outputs:
            base_root, base_manifest = load_kept(args.base_outputs)
            if base_commit and base_manifest.get("commit") != base_commit:
                raise SetupError(f"the kept base run is of {base_manifest.get('commit')}, not {base_commit}")
            missing = [s for s in sets if s not in base_manifest["sets"]]
            if missing:
                raise SetupError(f"set(s) {', '.join(missing)} not in the kept base run {base_root}")
            base_commit = base_manifest.get("commit")
        else:
            checkout = add_worktree(args.repo, base_commit, tmp / "checkout-base")
            worktrees.append(checkout)
            base_root = tmp / "run-base"
            base_manifest = run_side("base", checkout, base_root, sets, data, base_commit)
            bad_base = [(s, st["name"], st["rc"]) for s in sets for st in base_manifest["sets"][s]["steps"]
                        if st["rc"] not in (0, 1)]
            if bad_base:
                raise SetupError("base commands failed (these command lines do not fit the base): "
                                 + "; ".join(f"{s}/{n}: exit {rc}" for s, n, rc in bad_base)
                                 + f" (logs in {base_root / 'logs'}; use --keep to keep them)")

        head_dir = Path(args.head)
        head_commit = None
        if not head_dir.is_dir():
            head_commit = resolve_commit(args.repo, args.head)
            if head_commit is None:
                raise SetupError(f"--head {args.head} is neither a folder nor a commit of {args.repo}")
            head_dir = add_worktree(args.repo, head_commit, tmp / "checkout-head")
            worktrees.append(head_dir)
        head_dir = head_dir.resolve()
        if head_commit is None and (head_dir / ".git").exists():
            head_commit = git(head_dir, "rev-parse", "HEAD", check=False).stdout.strip() or None
        undone = undone_for(args.repo, base_commit)
        head_manifest = run_side("head", head_dir, tmp / "run-head", sets, data, head_commit, undone)

        base = Side(base_root, base_manifest, ignore=not args.no_ignore)
        head = Side(tmp / "run-head", head_manifest, ignore=not args.no_ignore, side="head")
        if base_manifest["check"]["versions"] != head_manifest["check"]["versions"] or \
                base_manifest["check"]["python"] != head_manifest["check"]["python"]:
            print(f"WARNING: the base run used other package versions: {base_manifest['check']['versions']} "
                  f"vs {head_manifest['check']['versions']}", file=sys.stderr)
        rows = [compare_set(s, base, head) for s in sets]
        dirty = head_commit and git(head_dir, "status", "--porcelain", "--untracked-files=no", check=False).stdout.strip()
        print(f"base {base_commit} ({'kept run ' + str(base_root) if args.base_outputs else 'temporary worktree'}) "
              f"vs head {head_dir}" + (f" ({head_commit}{' + uncommitted changes' if dirty else ''})" if head_commit else ""))
        print_table(rows)
        if not args.no_ignore:
            print_ignored(undone)
        if skipped:
            print(f"skipped (no real data): {', '.join(skipped)}")
        n = sum(len(r["diffs"]) for r in rows)
        print("identical" if n == 0 else f"{n} difference(s)")
        return 0 if n == 0 else 1
    except SetupError as e:
        print(f"same_outputs: {e}", file=sys.stderr)
        return 2
    finally:
        if args.keep:  # also after a failure: the logs say why
            for name in ("base", "head"):
                if (tmp / f"run-{name}" / MANIFEST).is_file():
                    keep(tmp / f"run-{name}", args.keep / name)
                    print(f"kept the {name} run in {args.keep / name}", file=sys.stderr)
        for w in worktrees:
            remove_worktree(args.repo, w)
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    raise SystemExit(main())
