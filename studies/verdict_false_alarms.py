"""How often does each check raise an alarm on correctly labelled trials? The paper's motions
(SIER: 25 s at 100 Hz, 1.5 mm noise, 20 mm per-marker artefact, as in the paper; abduction, flexion,
scaption: 10 s at 100 Hz) simulated with the per-marker artefact and with the artefact fitted on bone
pins (``--sta bone``), reconstructed by PF and LS together (their agreement enters the verdict, as
with ``exubio reconstruct --method both``): per motion and artefact the verdicts and every reason's
code with its count. A correctly labelled trial must never ``fail``.

    python studies/verdict_false_alarms.py --motions sier --seeds 100
    python studies/verdict_false_alarms.py --motions abduction flexion scaption --seeds 20
"""
from __future__ import annotations

import argparse
import collections
import logging
import time
import warnings

SETTINGS = {"sier": dict(duration_s=25.0, rate_hz=100.0, noise_mm=1.5, sta_mm=20.0),
            "abduction": dict(duration_s=10.0, rate_hz=100.0, noise_mm=1.5, sta_mm=20.0),
            "flexion": dict(duration_s=10.0, rate_hz=100.0, noise_mm=1.5, sta_mm=20.0),
            "scaption": dict(duration_s=10.0, rate_hz=100.0, noise_mm=1.5, sta_mm=20.0)}


def run_one(motion: str, seed: int, sta: str, methods):
    import exubio
    from exubio.synth.simulate import simulate_trial
    from exubio.synth.sta_bone import load_sta_model

    model = exubio.load_model()
    protocol = exubio.load_protocol(model=model)
    kw = dict(SETTINGS[motion])
    if sta == "bone":
        kw["sta_model"] = load_sta_model("bone")
        kw["sta_mm"] = 10.0  # the segments the pins do not cover keep a per-marker artefact
    sim = simulate_trial(model, motion, seed=seed, **kw)
    recs = []
    failed = []
    for m in methods:
        try:
            recs.append(exubio.reconstruct(sim.trajectories, model, protocol, method=m))
        except exubio.errors.ReconstructionError as exc:
            failed.append((m, str(exc)[:120]))
    out = {}
    if recs:
        assessment = exubio.assess(sim.trajectories, recs, model, protocol)
        for r in recs:
            q = assessment.quality[r.method]
            verdict = str(getattr(q.verdict, "value", q.verdict))
            codes = [(getattr(x, "level", ""), getattr(x, "code", "")) for x in q.reasons]
            out[r.method] = (verdict, codes, [x.message for x in q.reasons if getattr(x, "level", "") == "fail"])
    for m, reason in failed:
        out[m] = ("failed", [("fail", "reconstruction_failed")], [reason])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--motions", nargs="+", default=["sier"], choices=list(SETTINGS))
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--sta", nargs="+", default=["per-marker", "bone"], choices=["per-marker", "bone"])
    ap.add_argument("--methods", nargs="+", default=["pf", "ls"])
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    print("| motion | artefact | method | trials | ok | check | fail | reasons (level:code count) |")
    print("|---|---|---|---|---|---|---|---|")
    for motion in args.motions:
        for sta in args.sta:
            verdicts = {m: collections.Counter() for m in args.methods}
            reasons = {m: collections.Counter() for m in args.methods}
            fails = {m: [] for m in args.methods}
            t0 = time.perf_counter()
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                for m, (v, codes, fail_msgs) in run_one(motion, seed, sta, args.methods).items():
                    verdicts[m][v] += 1
                    reasons[m].update(f"{lv}:{c}" for lv, c in set(codes) if lv in ("check", "fail"))
                    fails[m] += [(seed, msg) for msg in fail_msgs]
            for m in args.methods:
                v = verdicts[m]
                text = ", ".join(f"{k} {n}" for k, n in reasons[m].most_common())
                print(f"| {motion} | {sta} | {m.upper()} | {sum(v.values())} | {v['ok']} | {v['check']} | "
                      f"{v['fail'] + v['failed']} | {text or '-'} |", flush=True)
                for seed, msg in fails[m][:3]:
                    print(f"|  |  |  | seed {seed} | fail: {msg[:150]} | | | |", flush=True)
            logging.getLogger(__name__).info("%s %s %.0f s", motion, sta, time.perf_counter() - t0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
