"""How closely can the lab's u be scaled to the bone's errors? The coverage of +-2u per trial and angle
(a cell) and pooled per angle over the trials, for the u multiplied by a factor k, on the S2M pin trials
(issue 33: "coverage between 90 and 99 % for every measured angle").

Each trial of ../shared/data/truth/sta_opendata is judged with the uncertainty model fitted on the other
trials there (exubio.truth.uncertainty_fit.fit_uncertainty_model: skin and girdle parts, one trial
out); the trials of --held DIR with the model fitted on all of them. LS, the u and status of a lab's run
with thorax markers (``AngleError.lab``), over each angle's measured frames; the frames measured are
those of k = 1 (a smaller u would measure a few more). Printed:

1. per cell the RMS of error / u, and across cells the spread of its logarithm, and the share of a
   cell's mean square error that is its mean (an offset over the whole trial);
2. per k: the cells below 90 %, in 90-99 % and above 99 % of their frames within +-2ku, and the same
   per angle for the frames of the trials not failed pooled (the coverage a 95 % band promises over a
   lab's trials), and over every pooled frame.

k is not fitted or chosen here: the table says what any single factor could do.

    python studies/bone_u_scale.py
    python studies/bone_u_scale.py --held /tmp/sta_more   # + S2M tasks not in ../shared (never fitted)

Data: Cereatti et al. 2017, J Biomech 62:5-13 (the ISB STA data-sharing sample; ../shared/data/truth/SOURCES.md).
The held-out tasks: STAOpenData/Data @ 33dd5a4, documents_and_data/dataSample/Matlab/, from a local folder.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from bone_common import RATE, bone_parser, quiet_generic_model
FACTORS = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2)


def judged_cells(path: Path, amplitude, generic) -> tuple[str, dict]:
    """(LS verdict, angle -> (signed error, u) over the measured frames, rad) of the lab's run."""
    from exubio.truth.compare import compare_bone_trial
    from exubio.truth.lab_run import setup_lab_run
    from exubio.truth.sta_format import read_sta_trial

    comp, _ = compare_bone_trial(setup_lab_run(read_sta_trial(path), generic, rate_hz=RATE), methods=("ls",),
                                 amplitude=amplitude)
    cells = {}
    for a, per in comp.angles.items():
        lab = getattr(per.get("ls"), "lab", None)
        if lab is not None and lab.error_rad is not None and lab.u_rad is not None and lab.error_rad.size:
            cells[a] = (lab.error_rad, lab.u_rad)
    return comp.verdicts.get("ls", ""), cells


def band(cov) -> tuple[int, int, int]:
    cov = np.asarray(cov)
    return int(np.sum(cov < 0.90)), int(np.sum((cov >= 0.90) & (cov <= 0.99))), int(np.sum(cov > 0.99))


def main(argv=None) -> int:
    args = bone_parser(__doc__).parse_args(argv)
    generic = quiet_generic_model(args.data)
    if generic is None:
        return 2
    from exubio.truth.uncertainty_fit import fit_uncertainty_model

    fitted = sorted(args.data.glob("*S2M*.mat"))
    trials = {}  # name -> (verdict, cells)
    for f in fitted:
        amp = fit_uncertainty_model([g for g in fitted if g != f], rate_hz=RATE, generic_model=generic).amplitude
        trials[f.stem] = judged_cells(f, amp, generic)
    if args.held is not None:
        amp = fit_uncertainty_model(fitted, rate_hz=RATE, generic_model=generic).amplitude
        for f in sorted(args.held.glob("*S2M*.mat")):
            trials[f.stem + " (held out)"] = judged_cells(f, amp, generic)
    cells = [(t, a, e, u) for t, (v, c) in trials.items() for a, (e, u) in c.items()]
    usable = {t for t, (v, _) in trials.items() if v != "fail"}
    print(f"{len(trials)} trials ({', '.join(f'{t}: {v}' for t, (v, _) in trials.items())}), {len(cells)} cells "
          "(trial x ST, GH, HT angle measured in some frame); LS, the u of a lab's run with thorax markers")
    z = np.array([np.sqrt(np.mean((e / u) ** 2)) for *_, e, u in cells])
    offset = np.array([np.mean(e) ** 2 / np.mean(e ** 2) for *_, e, u in cells])
    print(f"RMS of error / u per cell: median {np.median(z):.2f}, quartiles {np.percentile(z, 25):.2f}-"
          f"{np.percentile(z, 75):.2f}, range {z.min():.2f}-{z.max():.2f}; SD of its logarithm across cells "
          f"{np.std(np.log(z)):.2f} (a Gaussian error's 90-99 % band is RMS error / u within 0.78-1.22: +-0.22 in "
          "the logarithm)")
    print(f"share of a cell's mean square error that is its mean over the trial: median {np.median(offset):.2f}, "
          f"quartiles {np.percentile(offset, 25):.2f}-{np.percentile(offset, 75):.2f}")
    print("\n   k | cells below 90 / in 90-99 / above 99 % | pooled per angle, trials not failed: below / in / above"
          " | every pooled frame")
    angles = sorted({a for _, a, *_ in cells})
    for k in FACTORS:
        per_cell = [np.mean(np.abs(e) <= 2 * k * u) for *_, e, u in cells]
        pooled, tot_in, tot = [], 0, 0
        for a in angles:
            w = sum(int(np.sum(np.abs(e) <= 2 * k * u)) for t, b, e, u in cells if b == a and t in usable)
            n = sum(e.size for t, b, e, u in cells if b == a and t in usable)
            if n:
                pooled.append(w / n)
                tot_in, tot = tot_in + w, tot + n
        c, p = band(per_cell), band(pooled)
        print(f"{k:4.1f} | {c[0]:3d} / {c[1]:3d} / {c[2]:3d} of {len(per_cell)}"
              f"{'':18s}| {p[0]:3d} / {p[1]:3d} / {p[2]:3d} of {len(pooled)}{'':30s}| {100 * tot_in / max(tot, 1):.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
