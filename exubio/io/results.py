"""Write (and read back) reconstruction results: angle CSV, OpenSim .mot, .npz archive, JSON.

Every file is written atomically: the content goes to a temporary file in the target folder,
which then replaces the target with ``os.replace``. An interrupted or failing writer therefore
never leaves a half-written result, and an existing result is never truncated before the new one
is complete. ``atomic_write`` is public so that other writers (C3D, TRC, figures) can use it.

A result set (the files of one method's result: CSV, .mot, .npz, summary.json, ...) is complete or
absent (``ResultSet``): its files are written into a hidden staging folder in the output folder,
then a journal (``COMMIT.json``) says the set is complete, and only then are the files renamed into
place, summary.json last, with Ctrl-C and SIGTERM held back for those few renames. Without
overwrite a rename never replaces a file (``os.link``, which fails on an existing name). A run
killed while it writes leaves a staging folder named with its pid: the next run into that folder
removes it, or, when its journal is there (killed during the renames), finishes the renames. Two
runs never write one result set at once: ``claim`` holds a lock file created exclusively
(O_EXCL) per result stem for the run, and a second run is refused while the first one's process
runs. A full disk or any other OS error is an InputError naming the file.

Angles are radians in memory and degrees in the CSV and .mot files (labelled: the .mot header says
``inDegrees=yes``; the CSV holds degrees in every coordinate column, time in seconds).

Kept whole: the one place where results become files and files results again; each writer sits
beside its reader so that every round trip is seen (and tested, tests/io/test_io_results.py) together.
"""
from __future__ import annotations

import io
import json
import logging
import math
import os
import re
import secrets
import shutil
import signal
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from exubio.errors import InputError
from exubio.types import Gap, Reconstruction

logger = logging.getLogger(__name__)

_ANGLE_FORMAT = "%.6f"  # degrees: 1e-6 deg printed resolution
_TIME_FORMAT = "%.6f"  # seconds


# --------------------------------------------------------------------------------------------
# Atomic writing and the output folder
# --------------------------------------------------------------------------------------------
_IN_PROGRESS: dict[Path, None] = {}
"""Temporary files and folders this process is writing (removed by ``remove_in_progress`` when a
pool worker is stopped at once: exubio.run.executors.map_in_processes)."""


def in_progress(path: Path, /) -> Path:
    """Record ``path`` as a temporary file or folder being written (see ``done_with``)."""
    _IN_PROGRESS[Path(path)] = None
    return path


def done_with(path: Path, /) -> None:
    _IN_PROGRESS.pop(Path(path), None)


def remove_in_progress() -> None:
    """Remove every temporary file and folder this process is writing (a process stopping at once)."""
    for path in list(_IN_PROGRESS):
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            _remove_quietly(path)
        _IN_PROGRESS.pop(path, None)


def atomic_write(
    path: str | os.PathLike, writer: Callable[[Path], Any], /, *, temp_suffix: str | None = None
) -> Path:
    """Write ``path`` atomically: ``writer(tmp_path)`` writes the whole file at ``tmp_path`` (a
    fresh, empty, hidden file in the same folder), which then replaces ``path``. If ``writer``
    raises, the temporary file is removed, ``path`` is left as it was and the exception propagates.

    ``tmp_path`` ends with ``temp_suffix`` (default: the suffix of ``path``), for writers that
    choose the format from the name (matplotlib) or append their own suffix (ezc3d wants ".c3d").

    OS errors (missing folder, no permission, disk full) become InputError naming ``path``.
    Returns ``path`` as a Path.
    """
    target = Path(path)
    folder = target.parent
    if not folder.is_dir():
        raise InputError(f"{target}: cannot write, the folder '{folder}' does not exist")
    suffix = target.suffix if temp_suffix is None else temp_suffix
    tmp = in_progress(folder / f".{target.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp{suffix}")
    try:
        with open(tmp, "xb"):  # created empty, with the usual umask-based permissions
            pass
        writer(tmp)
        _fsync(tmp)
        os.replace(tmp, target)
    except OSError as exc:
        _remove_quietly(tmp)
        raise InputError(f"{target}: cannot write ({exc})") from exc
    except BaseException:
        _remove_quietly(tmp)
        raise
    finally:
        done_with(tmp)
    logger.debug("wrote %s", target)
    return target


def _fsync(path: Path) -> None:
    with open(path, "rb") as fh:
        os.fsync(fh.fileno())


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:  # pragma: no cover - e.g. permission lost meanwhile
        logger.warning("could not remove temporary file %s: %s", path, exc)


def _write_text(path: str | os.PathLike, text: str) -> Path:
    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)

    return atomic_write(path, writer)


def writable_folder(folder: str | os.PathLike, /, *, label: str | None = None) -> Path:
    """Create ``folder`` (with parents) and check that a file can be created in it (a temporary one,
    removed at once): an existing file, a folder that cannot be created or written is an InputError
    named ``label`` (default: the folder), found before any work."""
    import tempfile

    folder = Path(folder)
    label = label or str(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{label}: {folder} is an existing file, not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{label}: cannot create the folder {folder} ({exc.strerror or exc})") from None
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".exubio-write-test-"):
            pass
    except OSError as exc:
        raise InputError(f"{label}: cannot write in the folder {folder} ({exc.strerror or exc})") from None
    return folder


def prepare_output_dir(out_dir: str | os.PathLike, stems: Sequence[str], /, *, overwrite: bool) -> Path:
    """Create ``out_dir`` (with parents) and check that no result of this run exists there yet.

    Each entry of ``stems`` is a file name in ``out_dir`` (``"summary.json"``) or a stem without
    suffix (``"P01_ABD01_pf"``), which then stands for every file ``<stem>.<anything>``. When such a
    file exists and ``overwrite`` is False, an InputError names it. With ``overwrite=True`` nothing
    is deleted here: old files are replaced only by the writers' atomic renames.
    """
    folder = writable_folder(out_dir)
    for leftover in remove_leftovers(folder, stems):
        logger.info("removed %s, left by a run that was killed", leftover)
    existing = _existing_targets(folder, stems)
    if existing and not overwrite:
        names = ", ".join(str(p) for p in existing)
        raise InputError(
            f"{existing[0]}: result file already exists (existing: {names}); pass --overwrite to "
            f"replace the results or choose another output folder"
        )
    if existing:
        logger.info("%d existing result file(s) in %s will be replaced", len(existing), folder)
    return folder


_TEMP_NAME = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.tmp(\..*)?$")
_SET_SUFFIX = ".set"  # a ResultSet's staging folder: .<stem>.<pid>.<hex>.tmp.set
_JOURNAL = "COMMIT.json"


def remove_leftovers(folder: Path, stems: Sequence[str], /) -> list[Path]:
    """Remove what writers of the results ``stems`` (see prepare_output_dir) left when they were
    killed: hidden temporary files (``atomic_write``'s, exubio.io.streamed's part files) and
    ResultSet staging folders whose process (the pid in their name) no longer runs; a staging folder
    whose journal says its set was complete is first committed (its remaining renames done). A
    running writer's files are left alone."""
    removed = []
    for p in sorted(folder.iterdir()):
        m = _TEMP_NAME.match(p.name)
        if not m or _process_runs(int(m["pid"])):
            continue
        if not any(m["name"] == stem or m["name"].startswith(stem + ".") for stem in stems):
            continue
        if p.is_dir() and p.name.endswith(".tmp" + _SET_SUFFIX):
            _recover_set(p, folder)
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
        elif p.is_file():
            _remove_quietly(p)
            removed.append(p)
    return removed


def remove_after_interrupt(folder: str | os.PathLike, stems: Sequence[str], /, *, wait_s: float = 1.0) -> list[Path]:
    """After Ctrl-C stopped workers this process does not own (Dask's): wait up to ``wait_s`` for the
    processes named in the leftovers of ``stems`` in ``folder`` to end, then remove the leftovers
    and the locks of runs that no longer run (what the next run would remove)."""
    import time

    folder = Path(folder)
    if not folder.is_dir():
        return []
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        pids = {int(m["pid"]) for p in folder.iterdir() if (m := _TEMP_NAME.match(p.name))}
        pids |= {pid for stem in stems if (pid := _lock_owner(folder / f".{stem}.lock")[0])}
        if not any(pid != os.getpid() and _process_runs(pid) for pid in pids):
            break
        time.sleep(0.05)
    removed = remove_leftovers(folder, stems)
    for stem in stems:
        lock = folder / f".{stem}.lock"
        pid, started = _lock_owner(lock)
        if pid and pid != os.getpid() and not (_process_runs(pid) and started in (None, _start_time(pid))):
            _remove_quietly(lock)
            removed.append(lock)
    return removed


def _recover_set(staging: Path, folder: Path) -> None:
    """Finish the renames of a set killed while committing (its journal lists them, in order)."""
    journal = staging / _JOURNAL
    if not journal.is_file():
        return  # killed before the set was complete: nothing of it was placed
    try:
        names = json.loads(journal.read_text(encoding="utf-8"))["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    finished = []
    for name in names:
        staged = staging / name
        if staged.is_file():
            os.replace(staged, folder / name)
            finished.append(name)
    if finished:
        logger.info("%s: finished placing %s, the rest of a result set whose run was killed while it placed it",
                    folder, ", ".join(finished))


@contextmanager
def claim(folder: str | os.PathLike, stems: Sequence[str], /) -> Iterator[None]:
    """Hold, for the block, a lock file ``.<stem>.lock`` per stem in ``folder``, created exclusively
    (O_EXCL) and holding this process's pid: a second run for one of these results is refused
    (InputError) while the first one's process runs; a lock whose process is gone (killed) is taken
    over. The locks are removed at the end of the block."""
    folder = Path(folder)
    held: list[Path] = []
    try:
        for stem in stems:
            held.append(_lock(folder / f".{stem}.lock", stem))
        yield
    finally:
        for lock in held:
            _remove_quietly(lock)
            done_with(lock)


EMPTY_LOCK_GRACE_S = 2.0
"""An empty lock file younger than this (s) is being written (its creator writes its pid right after
creating it); older, it was left by a run killed between the two (SIGKILL) and is taken over."""


def _lock(path: Path, stem: str) -> Path:
    import time

    deadline = time.monotonic() + 2 * EMPTY_LOCK_GRACE_S + 1.0
    while time.monotonic() < deadline:
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            pid, started = _lock_owner(path)
            if pid is None:  # empty: its creator is writing its pid this instant, or was killed doing so
                age = _age_s(path)
                if age is not None and age < EMPTY_LOCK_GRACE_S:
                    time.sleep(0.02)
                    continue
                if age is not None:
                    logger.warning("%s: took over the lock %s, empty for %.0f s: left by a run killed while it "
                                   "took the lock", path.parent / stem, path.name, age)
            elif pid and _process_runs(pid) and started in (None, _start_time(pid)):  # not a reused pid
                raise InputError(f"{path.parent / stem}: another exubio run (process {pid}) is writing this result "
                                 f"in {path.parent}; wait for it to end or choose another output folder") from None
            elif pid:
                logger.warning("%s: took over the lock %s of process %d, which no longer runs (its run was killed)",
                               path.parent / stem, path.name, pid)
            _remove_quietly(path)
            continue
        except OSError as exc:
            raise InputError(f"{path.parent}: cannot write ({exc.strerror or exc})") from None
        in_progress(path)
        try:
            started = _start_time(os.getpid())
            os.write(fd, f"{os.getpid()}{'' if started is None else f' {started}'}".encode("ascii"))
        except OSError as exc:
            _remove_quietly(path)
            raise InputError(f"{path.parent}: cannot write ({exc.strerror or exc})") from None
        finally:
            os.close(fd)
        return path
    raise InputError(f"{path.parent / stem}: another exubio run keeps taking the lock {path.name} of this result in "
                     f"{path.parent}; wait for it to end or choose another output folder")


def _age_s(path: Path) -> float | None:
    """Seconds since ``path`` was last written, None when it is gone."""
    import time

    try:
        return max(time.time() - path.stat().st_mtime, 0.0)
    except OSError:
        return None


def _lock_owner(path: Path) -> tuple[int | None, int | None]:
    """(pid, start time) in a lock file: pid None when it is empty (being written) or unreadable, 0
    when the lock is gone; start time None where the system does not say (see _start_time)."""
    try:
        fields = path.read_text(encoding="ascii").split()
    except FileNotFoundError:
        return 0, None
    except (OSError, UnicodeDecodeError):
        return None, None
    if not fields or not all(f.isdigit() for f in fields):
        return None, None
    return int(fields[0]), (int(fields[1]) if len(fields) > 1 else None)


def _start_time(pid: int) -> int | None:
    """When process ``pid`` started (clock ticks since boot, Linux /proc), so that a lock whose pid
    was reused by another process after its run was killed is not taken for a running run; None
    where there is no /proc."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError):
        return None
    try:
        return int(stat.rsplit(")", 1)[1].split()[19])  # field 22: starttime (fields after the name)
    except (IndexError, ValueError):
        return None


class ResultSet:
    """The files of one result set (``<stem>.*`` in ``folder``), complete or absent (see the module docstring).
    ``path(name)`` is where a writer writes the file ``name`` (in the staging folder); ``commit()``
    places them all and returns their final paths; leaving the ``with`` block by an exception
    removes the staging folder, so nothing of the set appears."""

    def __init__(self, folder: str | os.PathLike, stem: str, /, *, overwrite: bool) -> None:
        self.folder, self.overwrite = Path(folder), overwrite
        self.staging = self.folder / f".{stem}.{os.getpid()}.{secrets.token_hex(4)}.tmp{_SET_SUFFIX}"
        try:
            self.staging.mkdir()
        except OSError as exc:
            raise InputError(f"{self.folder}: cannot write ({exc.strerror or exc})") from None
        in_progress(self.staging)
        self.names: list[str] = []

    def path(self, name: str) -> Path:
        if name not in self.names:
            self.names.append(name)
        return self.staging / name

    def commit(self, *, last: str | None = None) -> dict[str, Path]:
        """Place every file (``last`` after the others); a name taken meanwhile without overwrite
        undoes the placing and is an InputError naming it."""
        names = [n for n in self.names if n != last] + ([last] if last in self.names else [])
        write_json(self.staging / _JOURNAL, {"files": names})
        _fsync_folder(self.staging)
        placed: list[Path] = []
        with _signals_held():
            try:
                for name in names:
                    staged, final = self.staging / name, self.folder / name
                    if self.overwrite:
                        os.replace(staged, final)
                    else:
                        _place_new(staged, final)  # FileExistsError when the name is taken: never replaced
                        placed.append(final)
                _fsync_folder(self.folder)
            except OSError as exc:
                for final in placed:
                    _remove_quietly(final)
                _remove_quietly(self.staging / _JOURNAL)
                if isinstance(exc, FileExistsError):
                    raise InputError(f"{exc.filename2 or exc.filename}: result file already exists (written "
                                     f"meanwhile by another run); pass --overwrite to replace the results") from None
                raise InputError(f"{self.folder}: cannot place the result files ({exc.strerror or exc})") from None
        self.discard()
        return {name: self.folder / name for name in names}

    def discard(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)
        done_with(self.staging)

    def __enter__(self) -> "ResultSet":
        return self

    def __exit__(self, exc_type, exc: BaseException | None, tb: object) -> None:
        if self.staging.exists():
            self.discard()
        if isinstance(exc, InputError) and str(self.staging) in str(exc):  # name the file, not its staging place
            raise InputError(str(exc).replace(str(self.staging), str(self.folder))) from None


def _place_new(staged: Path, final: Path) -> None:
    """Move ``staged`` to ``final``, which must not exist: a hard link (fails on an existing name,
    atomically), then the staged name goes. On a file system without hard links (FAT, some network
    shares) a rename after a check, which another process could race."""
    import errno

    try:
        os.link(staged, final)
    except FileExistsError:
        raise
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.ENOSYS, errno.EMLINK):
            raise
        if final.exists():
            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(final)) from None
        os.rename(staged, final)
        return
    staged.unlink()


@contextmanager
def _signals_held() -> Iterator[None]:
    """Hold back Ctrl-C and SIGTERM while a set's files are placed: their handlers are replaced by
    one that notes the signal, and the original handlers get the noted signals afterwards (a
    KeyboardInterrupt then comes once the set is whole). Done with Python handlers, not a signal
    mask: a mask holds only the main thread's signals, and the kernel gives a process's signal to
    any thread that does not block it (numerical libraries run threads). Outside the main thread
    (where handlers cannot be set) nothing is held."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(sig)
        if handler in (signal.SIG_IGN, None):
            continue
        previous[sig] = handler
        signal.signal(sig, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for sig in pending:
            handler = previous[sig]
            if callable(handler):
                handler(sig, None)
            else:  # SIG_DFL
                signal.raise_signal(sig)


def _fsync_folder(folder: Path) -> None:
    """Make the renames in ``folder`` durable (where the OS can open a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _process_runs(pid: int) -> bool:
    if os.name == "nt":  # os.kill(pid, 0) would send CTRL_C_EVENT there: cannot tell, keep the files
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):  # another user's process, or cannot tell: keep its files
        return True
    return True


def _existing_targets(folder: Path, stems: Sequence[str]) -> list[Path]:
    if isinstance(stems, str):
        raise TypeError("stems must be a list of names, not a single string")
    entries = sorted(p.name for p in folder.iterdir())
    hits: list[Path] = []
    for stem in stems:
        for name in entries:
            if name == stem or name.startswith(stem + "."):
                hits.append(folder / name)
    return sorted(set(hits))


# --------------------------------------------------------------------------------------------
# Angles: CSV and OpenSim .mot
# --------------------------------------------------------------------------------------------
def _check_angles(path: Path, time_s: np.ndarray, names: Sequence[str], q_rad: np.ndarray) -> tuple:
    time = np.asarray(time_s, dtype=float)
    q = np.asarray(q_rad, dtype=float)
    names = tuple(str(n) for n in names)
    if time.ndim != 1:
        raise InputError(f"{path}: time must be 1-D, got shape {time.shape}")
    if q.shape != (time.shape[0], len(names)):
        raise InputError(
            f"{path}: angles have shape {q.shape}, expected (n_frames, n_coordinates) = "
            f"({time.shape[0]}, {len(names)})"
        )
    if len(set(names)) != len(names):
        raise InputError(f"{path}: duplicate coordinate names in {list(names)}")
    for name in names:
        if not name or name != name.strip() or any(c in name for c in ",\t\r\n\""):
            raise InputError(
                f"{path}: coordinate name {name!r} cannot be a column header "
                f"(expected a non-empty name without commas, tabs, quotes or surrounding spaces)"
            )
    return time, names, q


TABLE_BLOCK_ROWS = 20000  # text tables are formatted and written this many rows at a time


def _table_text(time: np.ndarray, q_deg: np.ndarray, sep: str) -> str:
    if time.shape[0] == 0:
        return ""
    buf = io.StringIO()
    fmt = [_TIME_FORMAT] + [_ANGLE_FORMAT] * q_deg.shape[1]
    np.savetxt(buf, np.column_stack([time, q_deg]), fmt=fmt, delimiter=sep)
    return buf.getvalue()


def _write_table(path: Path, head: str, time: np.ndarray, q_rad: np.ndarray, sep: str,
                 as_is: np.ndarray | None = None) -> Path:
    """``head`` then the rows (time, degrees; the columns ``as_is`` (bool mask) unconverted),
    formatted a block of rows at a time (a long trial's table is never one string in memory)."""
    def writer(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(head)
            for a in range(0, time.shape[0], TABLE_BLOCK_ROWS):
                b = min(a + TABLE_BLOCK_ROWS, time.shape[0])
                block = np.degrees(q_rad[a:b])
                if as_is is not None:
                    block[:, as_is] = q_rad[a:b][:, as_is]
                fh.write(_table_text(time[a:b], block, sep))

    return atomic_write(path, writer)


UNCERTAINTY_SUFFIX = "_u_deg"
"""The column of an angle's standard uncertainty, beside ``<angle>_deg`` in the angles CSV."""


def write_angles_csv(
    path: str | os.PathLike, time_s: np.ndarray, coordinate_names: Sequence[str], q_rad: np.ndarray, /, *,
    comments: Sequence[str] = (), uncertainty_rad: np.ndarray | None = None,
) -> Path:
    """Plain CSV: optional ``# comment`` lines (e.g. the Euler sequences of ISB angles), the header
    ``time_s,<coordinate names as in the model>``, then one row per frame, time in seconds and
    angles in DEGREES, ``%.6f``. NaN is written ``nan``. ``uncertainty_rad`` (n, a): each angle's
    standard uncertainty, written in degrees in a column ``<angle>_u_deg`` right after the angle's
    (``<name>_deg``; ``inf`` where the angle is not measured at all)."""
    path = Path(path)
    time, names, q = _check_angles(path, time_s, coordinate_names, q_rad)
    head = "".join(f"# {c}\n" for c in comments)
    if uncertainty_rad is not None:
        u = np.asarray(uncertainty_rad, dtype=float)
        if u.shape != q.shape:
            raise InputError(f"{path}: uncertainty has shape {u.shape}, the angles {q.shape}")
        names = tuple(c for n in names for c in (n, n.removesuffix("_deg") + UNCERTAINTY_SUFFIX))
        q = np.stack([q, u], axis=2).reshape(q.shape[0], -1)
    return _write_table(path, head + ",".join(("time_s",) + names) + "\n", time, q, ",")


def read_angles_csv(path: str | os.PathLike, /, *, uncertainty: bool = False):
    """Read a file of ``write_angles_csv``: (time_s, coordinate names, q in radians), the uncertainty
    columns left out; with ``uncertainty``, also their values (n, a) rad, NaN where the file has none."""
    path = Path(path)
    lines = _read_lines(path)
    skip = next((i for i, line in enumerate(lines) if not line.startswith("#")), len(lines))
    lines = lines[skip:]
    if not lines or lines[0].split(",")[0].strip() != "time_s":
        raise InputError(f"{path}: line {skip + 1}: expected a header starting with 'time_s', got {lines[:1]}")
    header = lines[0].split(",")
    names = tuple(h.strip() for h in header[1:])
    rows = [_parse_row(path, skip + i + 2, line.split(","), len(header)) for i, line in enumerate(lines[1:])
            if line.strip()]
    table = np.array(rows, dtype=float).reshape(len(rows), len(header))
    is_u = np.array([n.endswith(UNCERTAINTY_SUFFIX) for n in names], dtype=bool)
    angles = tuple(n for n, u in zip(names, is_u) if not u)
    values = np.radians(table[:, 1:][:, ~is_u])
    if not uncertainty:
        return table[:, 0].copy(), angles, values
    u_of = {n.removesuffix(UNCERTAINTY_SUFFIX): j for j, n in enumerate(names) if is_u[j]}
    u = np.full(values.shape, np.nan)
    for k, n in enumerate(angles):
        j = u_of.get(n.removesuffix("_deg"))
        if j is not None:
            u[:, k] = np.radians(table[:, 1 + j])
    return table[:, 0].copy(), angles, values, u


def read_angles_comments(path: str | os.PathLike, /) -> list[str]:
    """The ``# comment`` lines at the head of a file of ``write_angles_csv`` (without the '# ')."""
    path = Path(path)
    out = []
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            for line in fh:
                if not line.startswith("#"):
                    break
                out.append(line[1:].strip())
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from exc
    return out


def write_mot(
    path: str | os.PathLike,
    time_s: np.ndarray,
    coordinate_names: Sequence[str],
    q_rad: np.ndarray,
    /,
    *,
    name: str = "exubio",
    notes: Sequence[str] = (),
    metres: Sequence[str] = (),
) -> Path:
    """OpenSim motion file (.mot, storage version 1): angles in degrees (``inDegrees=yes``),
    tab-separated, ``time`` then the coordinates. ``notes``: single-line ``key=value`` remarks
    written in the header before ``endheader`` (e.g. coordinates that are not measurements).
    ``metres``: coordinates that are translations (m; e.g. the thorax's free joint,
    exubio.export.thorax): written as they are (OpenSim converts only rotational coordinates)."""
    path = Path(path)
    time, names, q = _check_angles(path, time_s, coordinate_names, q_rad)
    if "\n" in name or "\r" in name:
        raise InputError(f"{path}: .mot name must be a single line, got {name!r}")
    if any("\n" in n or "\r" in n or "=" not in n for n in notes):
        raise InputError(f"{path}: .mot header notes must be single 'key=value' lines, got {list(notes)!r}")
    header = (
        f"{name}\nversion=1\nnRows={time.shape[0]}\nnColumns={len(names) + 1}\n"
        f"inDegrees=yes\n" + "".join(f"{n}\n" for n in notes) + "endheader\n" + "\t".join(("time",) + names) + "\n"
    )
    unknown = sorted(set(metres) - set(names))
    if unknown:
        raise InputError(f"{path}: metres names {unknown}, which are not columns of the .mot")
    as_is = np.array([n in set(metres) for n in names], dtype=bool) if metres else None
    return _write_table(path, header, time, q, "\t", as_is)


def read_mot(path: str | os.PathLike, /) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """Read an OpenSim .mot/.sto of angles: (time_s, coordinate names, q in radians).
    Honours ``inDegrees`` (yes: degrees converted to radians; no: radians kept)."""
    path = Path(path)
    lines = _read_lines(path)
    header, body_start = _mot_header(path, lines)
    if body_start >= len(lines):
        raise InputError(f"{path}: no column line after 'endheader'")
    columns = [c.strip() for c in lines[body_start].split("\t")]
    if columns[0].lower() != "time":
        raise InputError(f"{path}: line {body_start + 1}: expected first column 'time', got '{columns[0]}'")
    rows = [
        _parse_row(path, body_start + 2 + i, line.split("\t"), len(columns))
        for i, line in enumerate(lines[body_start + 1 :])
        if line.strip()
    ]
    table = np.array(rows, dtype=float).reshape(len(rows), len(columns))
    _check_mot_counts(path, header, table.shape)
    in_degrees = header.get("indegrees", "no").lower() == "yes"
    q = np.radians(table[:, 1:]) if in_degrees else table[:, 1:]
    return table[:, 0].copy(), tuple(columns[1:]), q


def _mot_header(path: Path, lines: list[str]) -> tuple[dict[str, str], int]:
    header: dict[str, str] = {}
    for i, line in enumerate(lines):
        text = line.strip()
        if text.lower() == "endheader":
            return header, i + 1
        if "=" in text:
            key, value = text.split("=", 1)
            header[key.strip().lower()] = value.strip()
    raise InputError(f"{path}: not a .mot file: no 'endheader' line in {len(lines)} lines")


def _check_mot_counts(path: Path, header: Mapping[str, str], shape: tuple[int, int]) -> None:
    for key, actual in (("nrows", shape[0]), ("ncolumns", shape[1])):
        if key in header and header[key] != str(actual):
            raise InputError(f"{path}: header says {key}={header[key]} but the table has {actual}")


def _read_lines(path: Path) -> list[str]:
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return fh.read().splitlines()
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from exc


def _parse_row(path: Path, line_no: int, cells: list[str], n_columns: int) -> list[float]:
    if len(cells) != n_columns:
        raise InputError(f"{path}: line {line_no}: {len(cells)} columns, expected {n_columns}")
    try:
        return [float(c) for c in cells]
    except ValueError:
        raise InputError(f"{path}: line {line_no}: non-numeric value in {cells}") from None


# --------------------------------------------------------------------------------------------
# Full results: .npz
# --------------------------------------------------------------------------------------------
_NPZ_ARRAYS = (
    "time_s",
    "q_rad",
    "qd_rad_s",
    "qdd_rad_s2",
    "model_points_m",
    "measured_m",
    "residuals_m",
    "constraint",
    "constraint_velocity",
    "status",
)


def write_npz(path: str | os.PathLike, reconstruction: Reconstruction, /, *, metadata: Mapping[str, Any],
              extra_arrays: Mapping[str, np.ndarray] | None = None, streamed: Mapping[str, Any] | None = None) -> Path:
    """Every array of ``reconstruction`` (names as string arrays, gaps as three parallel arrays,
    timings/info as JSON) plus ``metadata`` JSON-encoded in the string entry ``metadata_json``,
    and ``extra_arrays`` (e.g. ``undetermined``: (n, m) bool, coordinates the markers do not
    determine in that frame). Uncompressed, loadable with ``np.load(path)`` (no pickle), the same
    layout as ``np.savez``. ``streamed``: arrays the reconstruction does not hold in memory (e.g.
    ``model_points_m`` of exubio.io.streamed), as objects with ``shape``, ``dtype``, ``complete``
    and ``blocks()`` (their rows in order), copied into the archive a block at a time."""
    rec = reconstruction
    streamed = dict(streamed or {})
    for key, source in streamed.items():
        if key not in _NPZ_ARRAYS or getattr(rec, key) is not None:
            raise ValueError(f"write_npz: streamed '{key}' must be a reconstruction entry it does not hold")
        if not source.complete:
            raise ValueError(f"write_npz: streamed '{key}' is incomplete")
    arrays: dict[str, Any] = {key: streamed.get(key, None) if key in streamed else np.asarray(getattr(rec, key))
                              for key in _NPZ_ARRAYS}
    for key, value in (extra_arrays or {}).items():
        if key in arrays or key in _NPZ_RESERVED:
            raise ValueError(f"write_npz: extra array '{key}' would replace a reconstruction entry")
        arrays[key] = np.asarray(value)
    arrays.update(
        method=np.array(rec.method),
        coordinate_names=np.array(rec.coordinate_names, dtype=str),
        marker_names=np.array(rec.marker_names, dtype=str),
        gap_markers=np.array([g.marker for g in rec.gaps], dtype=str),
        gap_start=np.array([g.start for g in rec.gaps], dtype=np.int64),
        gap_stop=np.array([g.stop for g in rec.gaps], dtype=np.int64),
        timings_json=np.array(_dumps(dict(rec.timings_s), strict=False)),
        info_json=np.array(_dumps(dict(rec.info), strict=False)),
        metadata_json=np.array(_dumps(dict(metadata), strict=False)),
    )

    def writer(tmp: Path) -> None:
        with zipfile.ZipFile(tmp, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for key, value in arrays.items():
                with zf.open(key + ".npy", "w", force_zip64=True) as fh:
                    if isinstance(value, np.ndarray):
                        np.lib.format.write_array(fh, value, allow_pickle=False)
                    else:  # rows from a file, a block at a time
                        header = {"descr": np.lib.format.dtype_to_descr(np.dtype(value.dtype)),
                                  "fortran_order": False, "shape": tuple(value.shape)}
                        np.lib.format.write_array_header_1_0(fh, header)
                        for block in value.blocks():
                            fh.write(np.ascontiguousarray(block, dtype=value.dtype).tobytes())

    return atomic_write(path, writer)


_NPZ_RESERVED = {"method", "coordinate_names", "marker_names", "gap_markers", "gap_start", "gap_stop",
                 "timings_json", "info_json", "metadata_json"}


POINT_ARRAYS = ("model_points_m", "measured_m")
"""The per-marker 3-D arrays of a result (~1 kB per frame with 22 markers): what a reader that only
needs the angles and residuals leaves on disk (``read_npz(..., points=False)``)."""


def read_npz(path: str | os.PathLike, /, *, points: bool = True) -> Reconstruction:
    """The Reconstruction stored by ``write_npz`` (metadata: see ``read_npz_metadata``). ``points``
    False: the model points and measured markers (POINT_ARRAYS) are not read (None), e.g. for a
    report of a long trial."""
    with _NpzReader(Path(path)) as data:
        gaps = tuple(
            Gap(str(m), int(a), int(b)) for m, a, b in zip(data["gap_markers"], data["gap_start"], data["gap_stop"])
        )
        return Reconstruction(
            method=str(data["method"]),
            coordinate_names=tuple(str(n) for n in data["coordinate_names"]),
            marker_names=tuple(str(n) for n in data["marker_names"]),
            timings_s=json.loads(str(data["timings_json"])),
            info=json.loads(str(data["info_json"])),
            gaps=gaps,
            **{key: (None if not points and key in POINT_ARRAYS else data[key]) for key in _NPZ_ARRAYS},
        )


def read_npz_metadata(path: str | os.PathLike, /) -> dict[str, Any]:
    """The ``metadata`` dict given to ``write_npz``."""
    with _NpzReader(Path(path)) as data:
        return json.loads(str(data["metadata_json"]))


def read_npz_arrays(path: str | os.PathLike, keys: Sequence[str], /) -> dict[str, np.ndarray]:
    """Extra arrays that ``write_npz`` stored (e.g. ``angle_status``, ``angle_names``,
    ``undetermined``); an InputError names the file and a key it lacks."""
    with _NpzReader(Path(path)) as data:
        return {k: np.asarray(data[k]) for k in keys}


class _NpzReader:
    """np.load with InputErrors naming the file and a missing key."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> "_NpzReader":
        try:
            self.data = np.load(self.path, allow_pickle=False)
        except FileNotFoundError:
            raise InputError(f"{self.path}: file not found") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # BadZipFile: truncated, damaged
            raise InputError(f"{self.path}: not a readable .npz file ({type(exc).__name__}: {exc}); expected an "
                             f"exubio result <trial>.<method>.npz, whole") from None
        if not isinstance(self.data, np.lib.npyio.NpzFile):  # a .npy array under an .npz name
            raise InputError(f"{self.path}: not an .npz archive (a single array: a .npy file?); expected an exubio "
                             f"result <trial>.<method>.npz")
        return self

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self.data[key]
        except KeyError:
            raise InputError(
                f"{self.path}: no entry '{key}' (not an exubio result?); entries are {sorted(self.data.files)}"
            ) from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # a damaged member (CRC, short)
            raise InputError(f"{self.path}: entry '{key}' is not readable ({type(exc).__name__}: {exc}); the file "
                             f"is damaged") from None

    def __exit__(self, *exc: object) -> None:
        self.data.close()


# --------------------------------------------------------------------------------------------
# JSON
# --------------------------------------------------------------------------------------------
def write_json(path: str | os.PathLike, data: Mapping[str, Any], /) -> Path:
    """Strict JSON, indent 2: numpy scalars/arrays become numbers/lists, tuples lists, paths
    strings, and NaN/inf become null."""
    return _write_text(path, _dumps(data, strict=True, indent=2) + "\n")


def _dumps(data: Any, *, strict: bool, indent: int | None = None) -> str:
    """JSON text. strict: NaN/inf → null (valid JSON); otherwise kept (Python's NaN extension),
    for exact round trips inside the .npz."""
    return json.dumps(_jsonable(data, strict), indent=indent, allow_nan=not strict)


def _jsonable(obj: Any, strict: bool) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v, strict) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist(), strict)
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [_jsonable(v, strict) for v in obj]
    if isinstance(obj, np.generic):
        return _jsonable(obj.item(), strict)
    if isinstance(obj, float):
        return None if strict and not math.isfinite(obj) else obj
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    raise TypeError(f"cannot write {type(obj).__name__} to JSON: {obj!r}")
