"""Every `exubio` example line of the bash blocks of the README and the docs site (docs/*.md) runs as written from a folder outside the
checkout (the installed console script, shipped protocols and models by name), each in a fresh
folder holding the files it names: simulated trials under the docs' names, the thoracoscapular
TRC trial of ../shared/data (skipped without it), and the files an earlier example makes (a
calibrated subject.yaml, results/trial.pf.npz). The few lines that need more than files are listed
in NOT_RUN with the reason and where they are tested."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from exubio.io.c3d import write_c3d
from exubio.model.load import load_model
from exubio.synth.simulate import simulate_trial

ROOT = Path(__file__).resolve().parents[2]
SHARED_TRC = ROOT.parent / "shared" / "data" / "trc" / "tsm_rmr_ABD01.trc"
SHARED_MAT = ROOT.parent / "shared" / "data" / "truth" / "sta_opendata" / "dataSample_S2M_armAbd.mat"
NOT_RUN = {
    "python3 -m venv": "the set-up commands: CI runs them (.ci/run)",
    "both_arms.c3d": "needs the lab's two per-arm protocols: tests/run/test_arms.py builds and runs them",
    "tcp://head": "needs a running Dask scheduler: --scheduler local:4 (the line before) is run",
    "exubio validate": "about 6 minutes: tests/report/test_report.py runs the validation study quick",
    "exubio stream": "needs a listener on LSL: tests/run/test_live.py runs stream and live together",
    "exubio live": "needs a stream on LSL: tests/run/test_live.py",
}

def study_file() -> str:
    """The study file of docs/studies.md, which the `exubio study` examples run."""
    text = (ROOT / "docs" / "studies.md").read_text(encoding="utf-8")
    return next(b for b in re.findall(r"```yaml\n(.*?)```", text, re.S) if "sessions:" in b)


DOCS = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]


def readme_lines() -> list[str]:
    """The example lines of every bash block of the README and the docs pages, in order."""
    text = "\n".join((ROOT / doc).read_text(encoding="utf-8") for doc in DOCS)
    lines = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        lines += [line.split("  #")[0].split(" # ")[0].strip() for line in block.splitlines()]
    return list(dict.fromkeys(line for line in lines if line.startswith("exubio ") or line.startswith("python3 -m venv")))


def _run(line: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONWARNINGS": "ignore"}
    return subprocess.run(["bash", "-c", line], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("readme_inputs")
    model = load_model()
    for name, motion, seed in (("trial", "abduction", 1), ("static", "abduction", 2), ("movement", "sier", 3),
                               ("arm_raised", "flexion", 4), ("raise", "scaption", 5), ("study/a", "abduction", 6),
                               ("study/b", "flexion", 7)):
        path = folder / f"{name}.c3d"
        path.parent.mkdir(exist_ok=True)
        duration = 0.6 if name == "static" else 2.0  # a short "static": the start of a movement
        write_c3d(path, simulate_trial(model, motion, duration_s=duration, rate_hz=50.0, noise_mm=0.5, seed=seed
                                       ).trajectories)
    (folder / "study.yaml").write_text(study_file(), encoding="utf-8")
    if SHARED_TRC.is_file():
        shutil.copy(SHARED_TRC, folder / "trial.trc")
    for mat in sorted(SHARED_MAT.parent.glob("dataSample_S2M_*.mat")):  # the bone trials the examples name
        shutil.copy(mat, folder / mat.name)
    return folder


PREREQUISITES = {  # a file an example reads that another example makes
    "subject.yaml": "exubio calibrate static.c3d --out subject.yaml",
    "results/trial.pf.npz": "exubio reconstruct trial.c3d --out results/",
}


def test_the_readme_has_the_examples_this_test_runs():
    lines = readme_lines()
    assert len(lines) >= 20
    assert any("--protocol thoracoscapular_9 " in line for line in lines)  # a shipped protocol by name
    assert not [line for line in lines if "protocols/" in line or "exubio/data" in line], \
        "an example names a file of the checkout: it does not run after pip install"


@pytest.mark.slow  # the commands end to end, 2-12 s each (about 90 s in all)
@pytest.mark.parametrize("line", [line for line in readme_lines()])
def test_a_readme_example_runs_from_a_folder_outside_the_checkout(line, inputs, tmp_path):
    skip = next((why for key, why in NOT_RUN.items() if key in line), None)
    if skip:
        pytest.skip(skip)
    if "trial.trc" in line and not (inputs / "trial.trc").is_file():
        pytest.skip(f"{SHARED_TRC} is absent")
    if SHARED_MAT.name in line and not (inputs / SHARED_MAT.name).is_file():
        pytest.skip(f"{SHARED_MAT} is absent")
    work = tmp_path / "lab"
    shutil.copytree(inputs, work)
    assert not str(work.resolve()).startswith(str(ROOT))
    for needed, make in PREREQUISITES.items():
        if needed in line.split(" --out ")[0] and not line.startswith(make):
            done = _run(make, work)
            assert done.returncode == 0, (make, done.stderr)
    done = _run(line, work)
    assert done.returncode == 0, (line, done.stdout[-2000:], done.stderr[-2000:])
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("doc", [*DOCS, "benchmarks/README.md", "studies/README.md"])
def test_every_file_the_docs_name_is_there(doc):
    """A module, test, benchmark, protocol, model source or figure the documentation points to or runs
    (`exubio/...py`, `tests/...py`, `python benchmarks/...py`, `python studies/...py`, `protocols/examples/...yaml`,
    `reports/.../...png`) exists: the README named `exubio/live/...` after the live loop had moved to
    `exubio/run/live/`."""
    text = (ROOT / doc).read_text(encoding="utf-8")
    named = set(re.findall(r"(?<![\w/.-])((?:exubio|tests|benchmarks|studies|models|protocols|reports|docs)/[\w/.-]+\.(?:py|yaml|png|pdf|json|csv|md))\b",
                           text))
    assert named, doc
    missing = sorted(p for p in named if not (ROOT / p).is_file())
    assert not missing, missing
