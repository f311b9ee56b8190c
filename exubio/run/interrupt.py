"""Ctrl-C, remembered. Python's handler raises KeyboardInterrupt wherever the main thread is; inside
Exudyn that exception does not always come out as itself: measured, a Ctrl-C while Exudyn's compiled
module was imported came out as ``ImportError: Exudyn could not import its compiled module``
(``.exudynCPP -> initialization failed``), and one while Exudyn's C++ read a Python list as
``RuntimeError: Error in Vector3DList::SetItem ... KeyboardInterrupt``. A run would report either as
a failed trial (a traceback, or a study going on to its next trial). The command line's handler
(``handler``) also notes the press; code that catches errors asks ``pressed()`` and stops as on
Ctrl-C (``exubio.cli``, a study's trial). ``held_back`` keeps a first Ctrl-C for the end of a block,
``kept_from_new_processes`` keeps it from the processes started in one."""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterator

_pressed = threading.Event()


def handler(signum, frame) -> None:  # noqa: ARG001 - the signal handler's signature
    """Python's Ctrl-C (KeyboardInterrupt), with the press noted."""
    _pressed.set()
    raise KeyboardInterrupt


def pressed() -> bool:
    """Whether Ctrl-C was pressed while ``noted()`` was on (an error caught since is its doing)."""
    return _pressed.is_set()


@contextmanager
def noted() -> Iterator[None]:
    """While in the block, Ctrl-C raises KeyboardInterrupt as Python's handler does and is noted
    (``pressed()``); on leaving, the note is cleared and the previous handler is back. Only where
    Python's handler is the one in place (in the main thread); elsewhere nothing changes."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    _pressed.clear()
    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _pressed.clear()


@contextmanager
def held_back() -> Iterator[list]:
    """A first Ctrl-C is noted (in the list yielded) and held back until the block ends, for work that
    must not be stopped half-done: a local Dask cluster stopped half-started (its worker processes
    being spawned from its event loop's thread) left a spawned child printing its traceback and
    multiprocessing's resource tracker warning of a leaked semaphore after exubio's one line; one
    that has started stops quietly (exubio.run.executors). A second Ctrl-C goes to the handler in
    place before (KeyboardInterrupt: at once). Only where a Python handler takes Ctrl-C, in the main
    thread; elsewhere nothing changes. (Inside ``kept_from_new_processes`` the main thread blocks
    SIGINT: a second Ctrl-C then comes at once only if another thread takes it, else at the end.)"""
    pressed: list = []
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(previous):
        yield pressed
        return

    def hold(signum, frame):
        if pressed:
            previous(signum, frame)
        pressed.append(signum)
        _pressed.set()  # a press all the same (pressed()), held or not

    signal.signal(signal.SIGINT, hold)
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def kept_from_new_processes() -> Iterator[None]:
    """While in the block, SIGINT is blocked in this thread's signal mask. Threads started meanwhile
    inherit the mask, and processes they start keep it: a terminal's Ctrl-C goes to the whole process
    group, and a Dask worker process that met it while it started (importing) printed its
    KeyboardInterrupt traceback and failed the cluster's start ("Nanny failed to start"). Such workers
    never see SIGINT; the run stops them itself. This process still gets a Ctrl-C meanwhile (another
    thread takes it, or it waits until the block ends): use it inside ``held_back`` to note it."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # started here, first: its start unblocks SIGINT in the thread starting it
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
