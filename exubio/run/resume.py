"""Resuming an interrupted run: a method's result set that an earlier run of the same inputs left
complete is kept, not refused and not computed again.

Every summary.json that ``exubio reconstruct`` writes carries ``inputs_sha256``: a fingerprint of
what the result is made from (the trial file's bytes and the labels read from it, the model and
protocol files (a calibrated model's file holds its calibration; a protocol with each file its
``extends`` chain reads, and the lab's uncertainty model it names), the method's options, the label
repair, exubio's code: ``code_fingerprint``, every source and data file of the installed package, not
its version string, which stays the same across the commits of a development install while the
results change). A plain re-run (no ``--overwrite``) finds a set complete (ResultSet:
summary.json is placed last) with the same fingerprint and keeps it: the results are
deterministic, so computing them again would give the same files. A set of other inputs is still
refused; ``--overwrite`` computes everything again.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any, Mapping, Sequence

from exubio.io.records import decode
from exubio.io.result_names import set_paths

CODE_SUFFIXES = (".py", ".pyi", ".json", ".yaml", ".yml", ".csv")
"""The files of the package that make a result: its code and the data it ships (the STA amplitude
model, the literature tables); not caches (``__pycache__``, numba's) or the example trial."""


def code_fingerprint(root: str | Path | None = None, /) -> str:
    """SHA-256 of every file of the exubio package (or of ``root``) with a suffix in ``CODE_SUFFIXES``,
    path and bytes, in path order: what the results of a given input depend on besides the input.
    Computed once per process for the package (about 10 ms)."""
    if root is None:
        return _package_fingerprint()
    root = Path(root)
    h = hashlib.sha256()
    for f in sorted(p for p in root.rglob("*") if p.suffix in CODE_SUFFIXES and "__pycache__" not in p.parts
                    and p.is_file()):
        h.update(f.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


_FINGERPRINT: list[str] = []


def _package_fingerprint() -> str:
    if not _FINGERPRINT:
        import exubio

        _FINGERPRINT.append(code_fingerprint(Path(exubio.__file__).resolve().parent))
    return _FINGERPRINT[0]


def run_key(trial_path: str | Path, model: Any, protocol: Any, method: str, /, *, options: Any = None,
            labels: Sequence[str] = (), repair_labels: bool = False) -> str | None:
    """The fingerprint of one method's run on one trial (see the module docstring); ``options``: the
    method's options object or a dict of its fields (None: the defaults). None when the trial, the
    model or the protocol is not a file (nothing to find again)."""
    import exubio
    from exubio.methods import method_spec

    files = [Path(trial_path), Path(str(model.source or "")), Path(str(protocol.source or ""))]
    if not all(f.is_file() for f in files):
        return None
    files[2:] = protocol_inputs(protocol)
    h = hashlib.sha256()
    for f in files:
        h.update(hashlib.sha256(f.read_bytes()).digest())
    opts = repr(method_spec(method).make_options(options))
    h.update(repr((method, tuple(labels), opts, bool(repair_labels), exubio.__version__, code_fingerprint())).encode())
    signs = getattr(protocol, "signs", "isb")
    if signs != "isb":  # the angles' sign convention (the protocol's key, or --signs over it): other files
        h.update(f"signs={signs}".encode())
    return h.hexdigest()


def protocol_inputs(protocol: Any, /) -> list[Path]:
    """The files a protocol's results depend on: its file, each file of its ``extends`` chain that gives
    it a key (a lab's base protocol edited between two runs gives other results) and the lab's uncertainty model it
    names (every angle's u comes from it)."""
    files = [Path(f) for f in (getattr(protocol, "files", ()) or (protocol.source,))]
    if getattr(protocol, "uncertainty_model", None):
        files.append(Path(protocol.uncertainty_model))
    return files


def kept_set(out_dir: str | Path, stem: str, key: str | None, /) -> Any:
    """The outcome (exubio.run.outcome.MethodOutcome: reconstruction, files, summary) of the result set
    ``stem`` in ``out_dir`` when it is complete and was made from the inputs ``key`` fingerprints;
    None otherwise. The reconstruction is read back without its model points
    (exubio.io.results.read_npz) and carries the verdict its summary.json gives and
    ``resumed_from`` (its summary.json)."""
    from exubio.io.results import read_npz
    from exubio.run.outcome import MethodOutcome
    from exubio.trust.quality import Quality

    if key is None:
        return None
    paths = set_paths(out_dir, stem)
    if not all(p.is_file() for p in paths.values()):
        return None
    try:
        summ = json.loads(paths["summary"].read_text(encoding="utf-8"))
        if summ.get("inputs_sha256") != key:
            return None
        recon = read_npz(paths["npz"], points=False)
        quality = decode(Quality, summ["quality"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    recon = dataclasses.replace(recon, quality=quality, resumed_from=str(paths["summary"]))
    return MethodOutcome(recon.method, stem, recon, paths=paths, summary=summ)


def fresh_report(report_files: Sequence[Path], sets: Sequence[Mapping[str, Path]], /) -> bool:
    """True when every file of a trial's report exists and is not older than any of its result
    sets' summary.json (a report an interrupted run left from before its sets is not fresh)."""
    if not report_files or not all(Path(p).is_file() for p in report_files):
        return False
    oldest = min(Path(p).stat().st_mtime_ns for p in report_files)
    return all(oldest >= Path(s["summary"]).stat().st_mtime_ns for s in sets)
