"""C3D files with random bytes changed in their header and parameter section, read by exubio: each
must be read or refused with a named reason (InputError), never crash the process (ezc3d reads past
its buffers on some sections) or raise anything else. Reads run in a child process that goes on
after a crash; prints the counts and every file that crashed or raised something else.

    .venv/bin/python studies/c3d_mutations.py [--n 500] [--seed 11] [--bytes 1,2,4,8] [--header]

--header mutates from the first byte (header included), else the parameter section only. The exubio
read is the one on PYTHONPATH (to compare with an older exubio, point PYTHONPATH at its checkout)."""
from __future__ import annotations

import argparse
import collections
import random
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

READER = r"""
import logging, sys
logging.disable(logging.CRITICAL)
from exubio.errors import InputError
from exubio.io.c3d import read_c3d
for f in sys.argv[1:]:
    print("START", f, flush=True)
    try:
        read_c3d(f)
        print("read", f, flush=True)
    except InputError:
        print("refused", f, flush=True)
    except Exception as exc:
        print("other", f, type(exc).__name__, flush=True)
"""


def mutants(folder: Path, n: int, seed: int, n_bytes: list[int], header: bool) -> list[Path]:
    from exubio.io.c3d import write_c3d
    from exubio.types import Trajectories

    traj = Trajectories(("A", "B", "C"), np.random.default_rng(0).uniform(-1, 1, (30, 3, 3)), 50.0, np.arange(30) / 50)
    base = bytearray(write_c3d(folder / "base.c3d", traj).read_bytes())
    first, end = (0 if header else (base[0] - 1) * 512), (struct.unpack("<H", base[16:18])[0] - 1) * 512
    rng, files = random.Random(seed), []
    for i in range(n):
        data = bytearray(base)
        for _ in range(rng.choice(n_bytes)):
            data[rng.randrange(first, end)] = rng.choice([rng.randrange(256), 32, 0, 255, 1])
        files.append(folder / f"m{i:04d}.c3d")
        files[-1].write_bytes(bytes(data))
    return files


def read_all(files: list[Path]) -> dict[str, str]:
    """file -> read / refused / other <exception> / crash <signal>, going on after a crash."""
    outcome: dict[str, str] = {}
    todo = [str(f) for f in files]
    while todo:
        done = subprocess.run([sys.executable, "-c", READER, *todo], capture_output=True, text=True, cwd=tempfile.gettempdir())
        started = None
        for line in done.stdout.splitlines():
            word, name, *rest = line.split(" ")
            if word == "START":
                started = name
            else:
                outcome[name], started = " ".join([word, *rest]), None
        if started is None:
            break
        outcome[started] = f"crash (exit {done.returncode})"
        todo = todo[todo.index(started) + 1:]
    return outcome


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--bytes", default="1,2,4,8", help="how many bytes a file has changed, drawn from these")
    parser.add_argument("--header", action="store_true", help="mutate the header too")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        files = mutants(Path(tmp), args.n, args.seed, [int(b) for b in args.bytes.split(",")], args.header)
        outcome = read_all(files)
    counts = collections.Counter(v.split()[0] for v in outcome.values())
    print(f"{args.n} files (seed {args.seed}, {args.bytes} bytes changed{', header too' if args.header else ''}): "
          + ", ".join(f"{k} {counts[k]}" for k in ("read", "refused", "other", "crash")))
    bad = {Path(k).name: v for k, v in outcome.items() if v.startswith(("other", "crash"))}
    for name, what in sorted(bad.items()):
        print(f"  {name}: {what}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
