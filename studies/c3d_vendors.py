"""Every file of the public C3D test suite (../shared/data/c3d_vendors: the c3d.org samples and
BTK's cases), read by exubio and by ezc3d, each in its own process (a reader that crashes on a
file shows as a crash, not as the end of the study). Prints a Markdown table: per file what exubio
does (read: markers, frames, rate, notes; refused: the reason) and what ezc3d does, then the
counts and the check that no file ezc3d reads points from is refused by exubio.

    .venv/bin/python studies/c3d_vendors.py [FOLDER] [--json OUT.json]

The exubio read is the one on PYTHONPATH (to compare with an older exubio, point PYTHONPATH at its
checkout)."""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT.parent / "shared" / "data" / "c3d_vendors"

EXUBIO = r"""
import json, logging, sys
logging.disable(logging.CRITICAL)
from exubio.errors import InputError
from exubio.io.c3d import read_c3d
try:
    t = read_c3d(sys.argv[1])
except InputError as exc:
    print(json.dumps({"refused": str(exc)}))
else:
    print(json.dumps({"markers": t.n_markers, "frames": t.n_frames, "rate": t.rate_hz,
                      "left_out": len(t.ignored_labels), "findings": list(t.input_findings)}))
"""
EZC3D = r"""
import json, sys, ezc3d
c = ezc3d.c3d(sys.argv[1])
print(json.dumps({"points": int(c["data"]["points"].shape[1]), "frames": int(c["data"]["points"].shape[2]),
                  "rate": float(c["header"]["points"]["frame_rate"])}))
"""


def run(code: str, path: Path) -> dict:
    """The JSON line a reader printed, or what it died of."""
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", str(ROOT))},
                          cwd=path.parent)  # not the current folder: `python -c` imports from there first
    if done.returncode == 0 and done.stdout.strip():
        return json.loads(done.stdout.strip().splitlines()[-1])
    if done.returncode < 0:
        return {"crash": f"killed by signal {-done.returncode}"}
    last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
    return {"error": last}


def short_notes(name: str, findings: list[str]) -> str:
    """The findings, one short clause each, repeated labels counted once."""
    clauses, duplicates, empty = [], 0, 0
    for f in findings:
        f = f.removeprefix(f"{name}: ")
        if re.search(r"\d+ (point|marker)s are labelled", f):
            duplicates += 1
        elif "has an empty label" in f:
            empty += 1
        else:
            clauses.append(f.split(";")[0].replace("parameter section: ", ""))
    if duplicates:
        clauses.append(f"{duplicates} label(s) on two points: the first with samples kept")
    if empty:
        clauses.append(f"{empty} empty label(s) left out")
    return "; ".join(clauses)


def exubio_cell(name: str, r: dict) -> str:
    if "refused" in r:
        return "refused: " + r["refused"].split(": ", 1)[-1].replace("|", "/")
    if "markers" not in r:
        return f"**{r.get('crash') or r.get('error')}**"
    left = f" ({r['left_out']} left out)" if r["left_out"] else ""
    notes = short_notes(name, r["findings"])
    return f"read: {r['markers']} markers{left}, {r['frames']} frames, {r['rate']:g} Hz" + (f"; {notes}" if notes else "")


def ezc3d_cell(r: dict) -> str:
    if "points" in r:
        return f"reads {r['points']} points, {r['frames']} frames, {r['rate']:g} Hz"
    return "refuses: " + (r.get("crash") or r["error"]).replace("|", "/")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", nargs="?", type=Path, default=DEFAULT)
    parser.add_argument("--json", type=Path, help="also write every reading as JSON here")
    args = parser.parse_args()
    files = sorted(p for p in args.folder.iterdir() if p.suffix.lower() == ".c3d")
    rows, table = [], ["| file | exubio | ezc3d 1.7.2 |", "|---|---|---|"]
    for path in files:
        ours, theirs = run(EXUBIO, path), run(EZC3D, path)
        rows.append({"file": path.name, "exubio": ours, "ezc3d": theirs})
        table.append(f"| {path.name} | {exubio_cell(path.name, ours)} | {ezc3d_cell(theirs)} |")
    print("\n".join(table))
    n_read = sum("markers" in r["exubio"] for r in rows)
    n_refused = sum("refused" in r["exubio"] for r in rows)
    n_ezc3d = sum(r["ezc3d"].get("points", 0) > 0 for r in rows)
    lost = [r["file"] for r in rows if r["ezc3d"].get("points", 0) > 0 and "markers" not in r["exubio"]]
    print(f"\n{len(rows)} files: exubio reads {n_read}, refuses {n_refused} (each naming the reason), "
          f"fails otherwise on {len(rows) - n_read - n_refused}; ezc3d reads 3-D points from {n_ezc3d}.")
    print("files ezc3d reads points from that exubio does not read: " + (", ".join(lost) or "none"))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1), encoding="utf-8")
    return 1 if lost else 0


if __name__ == "__main__":
    sys.exit(main())
