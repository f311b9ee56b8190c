"""The process's C heap: what a stage freed goes back to the system before the next one starts.

numpy's arrays of a long trial are allocated and freed stage after stage (reading, preparing, each
method's run, the assessment, the files). glibc returns a freed block to the system only when it was
mapped on its own (above its mmap threshold, which rises to 32 MB as large blocks are freed) or lies
at the top of the heap; the rest stays in the process, fragmented, counted in its resident memory
and not always reusable by the next stage's arrays of other sizes. ``malloc_trim`` gives those free
pages back. Between the stages of the 20-minute trial of ``benchmarks/bench_memory.py`` it lowers
PF's peak from 940 to 884 MB (``benchmarks/memory_stages.py --no-trim``; benchmarks/README.md, issue
38's memory bound). Elsewhere than glibc it does nothing.
"""
from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["release_freed_heap"]

_LIBC: list = []


def release_freed_heap() -> None:
    """Give the free pages of the C heap back to the system (glibc's ``malloc_trim(0)``; a no-op
    elsewhere). Cheap (milliseconds): called between the stages of a trial's run."""
    if not _LIBC:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _LIBC.append(libc.malloc_trim)
        except (OSError, AttributeError):  # not glibc
            _LIBC.append(None)
    if _LIBC[0] is not None:
        _LIBC[0](0)
