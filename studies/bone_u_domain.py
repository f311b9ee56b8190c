"""Where a lab's u still falls short on the bone pins, and two explanations measured.

1. The driver of the girdle's error. The uncertainty's girdle term grows with the humerus's rotation
   from rest, theta (exubio.truth.girdle). Would the scapula's own rotation from rest, phi, drive the
   model scapula's error better (the scapula moves in tasks where the humerus moves little)? Per S2M
   trial: the RMS of the model scapula's and humerus's frame errors with the markers carried by the
   bones (no skin), per RMS of theta and of phi (the bone's), and the spread of that ratio over the
   trials whose LS verdict is not fail (coefficient of variation: the lower, the better one pooled
   amplitude fits every task).
2. The domain of the bone data. Per judged trial (the shared tasks and, with --held, the tasks never
   fitted): every frame's humerus long axis (the bone's, in the thorax frame the lab run assumes)
   against the nearest humerus axis of the four shared S2M trials the shipped model was fitted on,
   in degrees; then, by bin of that distance, each ST and Phadke GH angle's coverage of +-2u (the u of
   a lab's run, LS, its measured frames), its RMS error and median u.

    python studies/bone_u_domain.py                    # the shared S2M trials
    python studies/bone_u_domain.py --held /tmp/sta_more  # + S2M tasks not in ../shared (armAdd, armExt, ...)

Data: Cereatti et al. 2017, J Biomech 62:5-13 (the ISB STA data-sharing sample; ../shared/data/truth/SOURCES.md).
The held-out tasks: STAOpenData/Data @ 33dd5a4, documents_and_data/dataSample/Matlab/, read from a local
folder, not copied into the project.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from bone_common import RATE, bone_parser, quiet_generic_model
ANGLES = ("ST_Y_internal_rotation", "ST_X_upward_rotation", "ST_Z_posterior_tilt", "GH_phadke_X_elevation",
          "GH_phadke_Y_internal_rotation")
BINS = ((0, 10), (10, 20), (20, 40), (40, 180))


def rotation_from_rest(rotation: np.ndarray, rest: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    R0 = Rotation.from_matrix(rotation[rest]).mean().as_matrix()
    return np.arccos(np.clip((np.einsum("ij,nij->n", R0, rotation) - 1.0) / 2.0, -1.0, 1.0))


def drivers(files: list[Path], generic) -> None:
    from exubio.truth.girdle import girdle_motion
    from exubio.truth.sta_amplitude import _rest
    from exubio.truth.sta_format import read_sta_trial

    print("1. the girdle's error (markers carried by the bones, LS) per RMS driver, rad per rad")
    print(f"   {'trial':18s} {'verdict':8s} {'|g scapula|':>11s} {'theta':>6s} {'phi':>6s}  "
          f"{'g_s/theta':>9s} {'g_s/phi':>8s} {'g_h/theta':>9s} {'g_h/phi':>8s}")
    ratios = {}
    for f in files:
        trial = read_sta_trial(f)
        m = girdle_motion(trial, generic, rate_hz=RATE)
        phi = rotation_from_rest(trial.segments["scapula"].rotation, _rest(trial, RATE))
        ok = np.isfinite(m.xi).all(axis=1) & np.isfinite(phi) & np.isfinite(m.theta)
        rms = lambda x: float(np.sqrt(np.mean(np.sum(np.atleast_2d(x.T).T ** 2, axis=-1))))
        gs, gh, th, ph = rms(m.xi[ok, :3]), rms(m.xi[ok, 3:]), rms(m.theta[ok]), rms(phi[ok])
        r = (gs / th, gs / ph, gh / th, gh / ph)
        if m.verdict != "fail":
            ratios[f.stem] = r
        print(f"   {f.stem[11:]:18s} {m.verdict:8s} {np.degrees(gs):11.1f} {np.degrees(th):6.1f} {np.degrees(ph):6.1f}  "
              + " ".join(f"{x:9.3f}" for x in r))
    v = np.array(list(ratios.values()))
    print("   coefficient of variation over the trials whose verdict is not fail: "
          + ", ".join(f"{n} {s:.2f}" for n, s in zip(("g_s/theta", "g_s/phi", "g_h/theta", "g_h/phi"),
                                                     v.std(axis=0) / v.mean(axis=0))))


def domain(fitted: list[Path], judged: list[Path], generic) -> None:
    from exubio.model.angles import anatomical_table
    from exubio.run.pipeline import reconstruct
    from exubio.truth.compare import angle_status, lab_inputs, truth_angles
    from exubio.truth.lab_run import setup_lab_run
    from exubio.truth.sta_format import read_sta_trial

    axes = []
    for f in fitted:
        a = setup_lab_run(read_sta_trial(f), generic, rate_hz=RATE).truth["humerus"][:, :, 1]
        axes.append(a[np.isfinite(a).all(axis=1)])
    F = np.concatenate(axes)
    print("\n2. coverage of +-2u (lab's u, LS, measured frames) by the humerus axis's distance (deg) to the "
          "shipped model's bone data")
    for f in judged:
        run = setup_lab_run(read_sta_trial(f), generic, rate_hz=RATE)
        model, inputs = lab_inputs(run)
        rec = reconstruct(inputs.model, inputs.protocol, inputs.targets, method="ls")
        det = angle_status(inputs, rec, still_thorax=False)
        names, table = anatomical_table(model, rec.q_rad)
        truth = truth_angles(run)
        a = run.truth["humerus"][:, :, 1]
        seen = np.isfinite(a).all(axis=1)
        dist = np.full(len(a), np.nan)
        dist[seen] = np.degrees(np.arccos(np.clip((a[seen] @ F.T).max(axis=1), -1.0, 1.0)))
        print(f"   {f.stem[11:]}: distance median {np.nanmedian(dist):.1f}, 90th percentile {np.nanpercentile(dist, 90):.1f}, "
              f"max {np.nanmax(dist):.1f} deg")
        for name in ANGLES:
            k, j = det.names.index(name), names.index(name)
            err = np.abs((table[:, j] - truth[name] + np.pi) % (2 * np.pi) - np.pi)
            u = det.uncertainty_rad[:, k]
            measured = det.status[:, k] == 0
            for lo, hi in BINS:
                s = measured & (dist >= lo) & (dist < hi)
                if s.sum() >= 20:
                    print(f"      {name:30s} {lo:3d}-{hi:3d} deg: {s.sum():5d} frames, coverage {np.mean(err[s] <= 2 * u[s]):4.0%}, "
                          f"RMS error {np.degrees(np.sqrt(np.mean(err[s] ** 2))):4.1f}, median u {np.degrees(np.median(u[s])):4.1f}")


def main(argv=None) -> int:
    args = bone_parser(__doc__).parse_args(argv)
    generic = quiet_generic_model(args.data)
    if generic is None:
        return 2
    shared = sorted(args.data.glob("dataSample_S2M_*.mat"))
    held = sorted(args.held.glob("dataSample_S2M_*.mat")) if args.held else []
    drivers(shared + held, generic)
    domain(shared, [f for f in shared + held if "punching" not in f.name and "ballThrowing" not in f.name], generic)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
