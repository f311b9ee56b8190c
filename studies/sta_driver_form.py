"""Which form of the skin's driver predicts a bone trial's artefact best (exubio.truth.sta_amplitude):
the shipped amplitude model makes each bone's cluster motion a zero-mean Gaussian of covariance
C d(theta)^2, theta the humerus's rotation from rest, d = theta_s tanh(theta / theta_s) (no saturation:
d = theta). For each theta_s, the model is fitted on three of the four S2M pin tasks of
../shared/data/truth/sta_opendata and judged on the fourth: the mean Gaussian log-likelihood per frame
of the held-out task's rigid cluster motions (the scapula's and the humerus's rotation vector and
translation, each bone alone), over its frames with the humerus at least 5 deg from rest, with a floor
of 0.06 deg and 0.1 mm SD so that a frame near rest does not decide alone. The skin's motion only: no
reconstruction, no angle, no coverage enters it. The shipped model keeps d = theta all the same: the
u made with theta_s = 0.5 rad covers the bone no better and far worse where the arm turns most
(exubio.truth.sta_amplitude's docstring; ``python studies/bone_u_driver.py --saturation 0.5 --data DIR``).

    python studies/sta_driver_form.py

Data: Cereatti et al. 2017, J Biomech 62:5-13 (the ISB STA data-sharing sample; ../shared/data/truth/SOURCES.md).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "truth" / "sta_opendata"
RATE = 300.0
FORMS = (None, 4.0, 2.0, 1.0, 0.5, 0.25)
FLOOR = np.diag([np.radians(0.06) ** 2] * 3 + [1e-4 ** 2] * 3)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.parse_args(argv)
    files = sorted(DATA.glob("dataSample_S2M_*.mat"))
    if len(files) < 2:
        print(f"no S2M trials at {DATA}", file=sys.stderr)
        return 2
    from exubio.truth import sta_amplitude as fit
    from exubio.truth.sta_format import read_sta_trial

    trials = {f.stem.split("_")[-1]: read_sta_trial(f) for f in files}
    motion = {}
    for task, t in trials.items():
        rest = fit._rest(t, RATE)
        x = {b: np.concatenate([v["rotation"], v["translation"]], axis=1)
             for b, v in ((b, fit.segment_sta(t, b, rest)) for b in ("scapula", "humerus"))}
        motion[task] = (fit.humerus_driver(t, rest), x)

    def loglik(task: str, amp) -> float:
        theta, x = motion[task]
        total, n = 0.0, 0
        for bone, X in x.items():
            ok = np.isfinite(X).all(axis=1) & (theta > np.radians(5))
            d = amp.skin_driver(theta[ok])
            S = amp.rigid[bone][None] * (d ** 2)[:, None, None] + FLOOR
            _, logdet = np.linalg.slogdet(S)
            maha = np.einsum("bi,bi->b", X[ok], np.linalg.solve(S, X[ok][..., None])[..., 0])
            total += float(np.sum(-0.5 * (logdet + maha + 6 * np.log(2 * np.pi))))
            n += int(ok.sum())
        return total / max(n, 1)

    print("mean log-likelihood per frame of the held-out task's cluster motions (higher is better)")
    print(f"{'theta_s (rad)':>14s} " + " ".join(f"{t:>10s}" for t in trials) + f" {'mean':>8s}")
    best = None
    for ts in FORMS:
        row = {}
        for task in trials:
            others = [(trials[o], RATE) for o in trials if o != task]
            row[task] = loglik(task, fit.fit_sta_amplitude(others, saturation_rad=ts))
        mean = float(np.mean(list(row.values())))
        print(f"{'none' if ts is None else f'{ts:g}':>14s} " + " ".join(f"{v:10.2f}" for v in row.values()) + f" {mean:8.2f}")
        if best is None or mean > best[1]:
            best = (ts, mean)
    print(f"best: theta_s = {best[0]} rad (shipped: d = theta; why, exubio.truth.sta_amplitude)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
