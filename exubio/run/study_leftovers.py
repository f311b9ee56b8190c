"""Leftovers of killed study runs: a study's temporary folders (``.tmp-<trial>-<pid>-<ns>``, a
trial; ``.tmp-calibration-<pid>``, a session's calibration) and the temporary files of atomic writes,
removed when their process no longer runs (exubio.run.study)."""
from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

__all__ = ["clean_leftovers"]

_TMP_PREFIX = ".tmp-"
_TMP_PID = re.compile(rf"^{re.escape(_TMP_PREFIX)}(?:calibration-(?P<cpid>\d+)|.+-(?P<pid>\d+)-\d+)$")
"""A study's temporary folders: .tmp-<trial>-<pid>-<ns> (a trial), .tmp-calibration-<pid> (a session's calibration)."""


def clean_leftovers(out_dir: Path, /) -> list[Path]:
    """Remove the temporary folders and files of killed runs: those whose process (the pid in their
    name) no longer runs; a running study's (another one into the same folder) are left alone."""
    from exubio.io.result_set import _TEMP_NAME, _process_runs

    removed = []
    for p in sorted(out_dir.rglob(f"{_TMP_PREFIX}*")):
        m = _TMP_PID.match(p.name)
        if p.is_dir() and not (m and _process_runs(int(m["pid"] or m["cpid"]))):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    for p in sorted(out_dir.rglob(".*.tmp*")):  # a file a killed writer left (atomic_write)
        m = _TEMP_NAME.match(p.name)
        if p.is_file() and not (m and _process_runs(int(m["pid"]))):
            p.unlink(missing_ok=True)
            removed.append(p)
    return removed


def _remove_after_dask(out_dir: Path, /, *, wait_s: float = 1.0) -> None:
    """clean_leftovers once the workers named in the leftovers have ended (at most ``wait_s``)."""
    deadline = time.monotonic() + wait_s
    from exubio.io.result_set import _process_runs

    while time.monotonic() < deadline:
        pids = {int(m["pid"] or m["cpid"]) for p in out_dir.rglob(f"{_TMP_PREFIX}*") if (m := _TMP_PID.match(p.name))}
        if not any(pid != os.getpid() and _process_runs(pid) for pid in pids):
            break
        time.sleep(0.05)
    clean_leftovers(out_dir)
