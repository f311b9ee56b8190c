"""The result set: how results become files, complete or absent, and never two runs at once.

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
runs. A full disk or any other OS error is an InputError naming the file. The formats of the files
are exubio.io.results'.
"""
from __future__ import annotations

import json
import logging
import os
import re
import secrets
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from exubio.errors import InputError

logger = logging.getLogger(__name__)

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
        _write_text(self.staging / _JOURNAL, json.dumps({"files": names}, indent=2) + "\n")
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
