"""What the model's girdle cannot follow of the bones, fitted on the S2M pin trials, and the u a lab's
run gives judged against the bones with and without it (exubio.truth.girdle,
exubio.trust.angle_uncertainty.girdle_angle_variance).

1. Per S2M trial of ../shared/data/truth/sta_opendata: the model's scapula and humerus ISB frames off
   the bones' with every skin marker carried rigidly by its bone (LS), RMS per axis by bin of the
   humerus's rotation theta; the trials whose LS verdict is `fail` are left out of the fit. The offset
   theta_0 the error's spread grows from (theta + theta_0) is chosen by its held-out likelihood
   (exubio.truth.girdle.offset_likelihoods: the table per offset); the fit
   (exubio.truth.girdle.fit_girdle) adds the girdle's covariance with what the skin adds.
2. The lab's u (no still-thorax term), LS, over each angle's measured frames: the coverage of +-2u of
   each ST, GH and HT angle and the fraction of frames measured, (a) without the girdle term, (b) with
   it fitted on the other fitted trials (one task out, the offset chosen on them) or, for the trials of
   --held DIR, on all of them; (c) the same with no offset (theta_0 = 0, the model before). Cells below
   90 % and above 99 % counted, the ones below listed.

    python studies/bone_u_girdle.py                       # the fit and the one-task-out coverage
    python studies/bone_u_girdle.py --held /tmp/sta_more  # + trials never fitted (S2M tasks not in ../shared)
    python studies/bone_u_girdle.py --write               # also write the fit into exubio/data/sta_amplitude_s2m.json

Data: Cereatti et al. 2017, J Biomech 62:5-13 (the ISB STA data-sharing sample; ../shared/data/truth/SOURCES.md).
The held-out tasks (S2M armAdd, armExt, behindBackReach, ballThrowing): STAOpenData/Data @ 33dd5a4,
documents_and_data/dataSample/Matlab/, read from a local folder, not copied into the project.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
from bone_common import RATE, ROOT, bone_parser, quiet_generic_model

SHIPPED = ROOT / "exubio" / "data" / "sta_amplitude_s2m.json"
BINS = ((0, 10), (10, 20), (20, 40), (40, 60), (60, 90), (90, 180))


def lab_coverage(path: Path, amplitude) -> dict:
    """angle -> (coverage, measured fraction) of the lab's u, LS, with ``amplitude``."""
    from exubio.errors import ModelError
    from exubio.io.yaml import read_yaml
    from exubio.model.load import DEFAULT_MODEL
    from exubio.truth.compare import compare_bone_trial
    from exubio.truth.lab_run import setup_lab_run
    from exubio.truth.sta_format import read_sta_trial

    run = setup_lab_run(read_sta_trial(path), read_yaml(DEFAULT_MODEL, error=ModelError), rate_hz=RATE)
    comp, _ = compare_bone_trial(run, methods=("ls",), amplitude=amplitude)
    VERDICTS[path.stem] = comp.verdicts.get("ls", "")
    return comp.lab_coverage("ls")


VERDICTS: dict = {}  # trial stem -> its LS verdict (the last lab_coverage run of it)


def summary(title: str, cells: dict) -> None:
    below = [(t, a, c, f) for t, per in cells.items() for a, (c, f) in per.items() if c < 0.9]
    above = sum(c > 0.99 for per in cells.values() for c, _ in per.values())
    n = sum(len(per) for per in cells.values())
    frac = np.mean([f for per in cells.values() for _, f in per.values()])
    usable = {t for t in cells if VERDICTS.get(t.split(" ")[0]) != "fail"}  # a lab does not use a failed trial's angles
    print(f"{title}: {n} measured angle cells, below 90 %: {len(below)} ({sum(t in usable for t, *_ in below)} of "
          f"{sum(len(cells[t]) for t in usable)} on the trials whose LS verdict is not fail), above 99 %: {above}, "
          f"mean fraction of frames measured {frac:.0%}")
    for t, a, c, f in below:
        print(f"    {t} {a}: {c:.0%} ({f:.0%} measured){'' if t in usable else ' [LS verdict fail]'}")


def main(argv=None) -> int:
    ap = bone_parser(__doc__)
    ap.add_argument("--write", action="store_true", help=f"write the fit into {SHIPPED.relative_to(ROOT)}")
    ap.add_argument("--no-coverage", action="store_true", help="the fit only")
    args = ap.parse_args(argv)
    generic = quiet_generic_model(args.data)
    if generic is None:
        return 2
    from exubio.trust.sta_amplitude import load_sta_amplitude
    from exubio.truth.girdle import fit_girdle, girdle_motion, girdle_offset, offset_likelihoods
    from exubio.truth.sta_format import read_sta_trial

    files = sorted(args.data.glob("*S2M*.mat"))
    motions = {f: girdle_motion(read_sta_trial(f), generic, rate_hz=RATE) for f in files}
    held = {} if args.held is None else {f: girdle_motion(read_sta_trial(f), generic, rate_hz=RATE)
                                         for f in sorted(args.held.glob("*S2M*.mat"))}
    print("girdle error with the markers carried by the bones (LS; RMS deg about the model frames' X, Y, Z)")
    for f, g in {**motions, **held}.items():
        th = np.degrees(g.theta)
        ok = np.isfinite(g.xi).all(axis=1)
        cells = []
        for lo, hi in BINS:
            s = ok & (th >= lo) & (th < hi)
            if s.sum() >= 10:
                r = np.degrees(np.sqrt(np.mean(g.xi[s] ** 2, axis=0)))
                cells.append(f"{lo}-{hi}: scapula {r[0]:.1f} {r[1]:.1f} {r[2]:.1f}, humerus {r[3]:.1f} {r[4]:.1f} {r[5]:.1f}")
        used = "held out" if f in held else "left out of the fit" if g.verdict == "fail" else "fitted"
        print(f"  {f.name} (verdict {g.verdict}: {used})")
        for c in cells:
            print(f"     theta {c}")
    lik = offset_likelihoods(list(motions.values()))
    print("the offset theta_0 (deg): mean held-out log-likelihood per frame of the girdle error, one fitted trial out")
    print("   " + "  ".join(f"{d:g}: {v:.2f}" for d, v in lik.items()))
    t0 = girdle_offset(list(motions.values()))
    C = fit_girdle(list(motions.values()), offset_rad=t0)
    fitted = [f for f, g in motions.items() if g.verdict != "fail"]
    d = np.diag(C)
    print(f"chosen theta_0 = {np.degrees(t0):.0f} deg; C's diagonal as sign x sqrt|.| (deg per rad of theta + theta_0; "
          "negative: the skin takes back more than the girdle misses about that axis): " + ", ".join(
              f"{n} {x:+.2f}" for n, x in zip(
              ("scapula X", "Y", "Z", "humerus X", "Y", "Z"), np.sign(d) * np.degrees(np.sqrt(np.abs(d))))))
    if args.write:
        data = json.loads(SHIPPED.read_text())
        amp = dataclasses.replace(load_sta_amplitude(), girdle=C, girdle_offset_rad=t0, girdle_source=(
            "studies/bone_u_girdle.py: exubio.truth.girdle.fit_girdle on " + ", ".join(f.name for f in fitted)
            + " (S2M, 300 Hz, LS; the frames' error with the markers carried rigidly by the bones and with the skin markers: "
            "var(g) + 2 cov(g, s); trials whose LS verdict is 'fail' with the markers carried by the bones left out; "
            f"offset theta_0 {np.degrees(t0):.0f} deg chosen on them, one trial out)"))
        new = amp.to_json()
        data.update({k: new[k] for k in ("girdle_second_moment", "girdle_second_moment_units", "girdle_driver_offset_rad",
                                         "girdle_source")})
        SHIPPED.write_text(json.dumps(data, indent=2) + "\n")
        print(f"written to {SHIPPED}")
    if args.no_coverage:
        return 0
    base = dataclasses.replace(load_sta_amplitude(), girdle=None, girdle_offset_rad=0.0)
    without, with_, no_offset = {}, {}, {}
    for f in fitted:
        others = [g for h, g in motions.items() if h != f]
        o = girdle_offset(others) if sum(g.verdict != "fail" for g in others) >= 2 else t0
        without[f.stem] = lab_coverage(f, base)
        with_[f.stem] = lab_coverage(f, dataclasses.replace(base, girdle=fit_girdle(others, offset_rad=o),
                                                            girdle_offset_rad=o))
        no_offset[f.stem] = lab_coverage(f, dataclasses.replace(base, girdle=fit_girdle(others)))
    if args.held is not None:
        for f in sorted(args.held.glob("*S2M*.mat")):
            without[f.stem + " (held out)"] = lab_coverage(f, base)
            with_[f.stem + " (held out)"] = lab_coverage(f, dataclasses.replace(base, girdle=C, girdle_offset_rad=t0))
            no_offset[f.stem + " (held out)"] = lab_coverage(f, dataclasses.replace(
                base, girdle=fit_girdle(list(motions.values()))))
    summary("the lab's u without the girdle term", without)
    summary("with it, no offset (theta_0 = 0; one task out; held-out trials: fitted on all)", no_offset)
    summary("with it and its offset (one task out, the offset chosen on the others; held-out trials: fitted on all)",
            with_)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
