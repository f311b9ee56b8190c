"""Check that ``exubio stream`` and ``exubio live`` talk to 127.0.0.1 only.

Runs both (the shipped example, 2 s of it) under ``strace -f`` recording every socket call that
names an address (bind, connect, sendto, sendmsg, sendmmsg), and lists the addresses seen per
call. With exubio's loopback lsl_api.cfg every destination must be 127.0.0.1; binds may be
127.0.0.1 or 0.0.0.0 (liblsl's listening ports). Exit 0 when that holds, 1 otherwise.

    python benchmarks/lsl_loopback_check.py
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ADDR = re.compile(r'(?:inet_addr|inet_pton)\((?:AF_INET6?, )?"([^"]+)"\)')
CALL = re.compile(r"^(?:\[pid\s+\d+\]\s+)?(?:\d+\s+)?(\w+)\(")


def main() -> int:
    if not shutil.which("strace"):
        print("strace is not installed")
        return 2
    from exubio.io.c3d import write_c3d
    from exubio.io.trial import read_trial
    from exubio.run.live.transport import use_config
    from exubio.types import Trajectories

    cfg = use_config("loopback")
    env = dict(os.environ, LSLAPICFG=str(cfg))
    exe = [sys.executable, "-m", "exubio.cli"]
    seen: dict[str, set] = defaultdict(set)
    with tempfile.TemporaryDirectory(prefix="exubio-lsl-check-") as tmp:
        tmp = Path(tmp)
        t = read_trial(ROOT / "exubio" / "data" / "example_abduction.c3d")
        short = tmp / "short.c3d"
        write_c3d(short, Trajectories(labels=t.labels, positions_m=t.positions_m[:200], rate_hz=t.rate_hz,
                                      time_s=t.time_s[:200], source="short"))
        trace = ["strace", "-f", "-qq", "-e", "trace=bind,connect,sendto,sendmsg,sendmmsg"]
        name = f"check_{os.getpid()}"
        live = subprocess.Popen(trace + ["-o", str(tmp / "live.trace")] + exe + [
            "live", "--stream", name, "--out", str(tmp), "--name", "c", "--no-report", "--end-after", "1.5", "-q"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        stream = subprocess.run(trace + ["-o", str(tmp / "stream.trace")] + exe + [
            "stream", str(short), "--name", name, "--wait", "30", "-q"], env=env, capture_output=True, text=True,
            timeout=300)
        out, err = live.communicate(timeout=300)
        print(f"exubio stream exit {stream.returncode}, exubio live exit {live.returncode}")
        for which in ("stream", "live"):
            for line in (tmp / f"{which}.trace").read_text().splitlines():
                call = CALL.match(line)
                for addr in ADDR.findall(line):
                    seen[f"{which}:{call.group(1) if call else '?'}"].add(addr)
    ok = True
    for key in sorted(seen):
        addrs = sorted(seen[key])
        allowed = {"127.0.0.1", "0.0.0.0"} if key.endswith(":bind") else {"127.0.0.1"}
        bad = [a for a in addrs if a not in allowed]
        ok &= not bad
        print(f"  {key:16s} {', '.join(addrs)}" + (f"   <-- NOT LOOPBACK: {bad}" if bad else ""))
    print("only 127.0.0.1 (binds: 127.0.0.1 / 0.0.0.0)" if ok else "TRAFFIC BEYOND 127.0.0.1")
    return 0 if ok and seen else 1


if __name__ == "__main__":
    sys.exit(main())
