"""Functional glenohumeral centre (SCoRE) and elbow flexion axis on real trials.

Data: ../shared/data/c3d (Ipuch/bioptim_exo @ b4a33b4e, MIT, "Copyright (c) 2022 Pierre"; see
../shared/data/SOURCES.md): bioptim_exo_martin_dynamique.c3d and
bioptim_exo_kinova_martin_dent_f3_1.c3d (labels "Martin:..." are stripped by the reader; the
"Kinova:" robot markers are not used). In the kinova_martin session RADIUS and ULNA are read the
other way round (protocols/examples/kinova_martin_session.yaml): they are swapped back here.

Segments (marker clusters, poses by cluster_poses on the SVD fit):
* acromion cluster SCAP_AC, SCAP_BACK, SCAP_FRONT (a rigid plate; the other scapula markers are
  skin markers). Its frame ("scapula cluster frame"): origin SCAP_AC, X from SCAP_BACK to
  SCAP_FRONT, Z normal to the plate, X x (SCAP_AC - SCAP_BACK), Y = Z x X; as at the first frame.
* thorax MAN, XYP, C7, T10; its frame is the ISB thorax frame at the first frame (origin MAN,
  Y from mid(XYP, T10) to mid(MAN, C7), Z normal to MAN, C7, mid(XYP, T10) to the right,
  X = Y x Z), so a centre fitted in it is in ISB thorax coordinates.
* humerus ARM, DELT, EPI_lat, EPI_med (ARM and DELT sit on soft tissue: skin motion).

GH: SCoRE between the acromion cluster (segment 1) and the humerus (segment 2), and thorax vs
humerus for comparison (that one lumps the scapula's motion on the thorax into the "joint", so it
cannot be a fixed point: expect a larger mismatch).

Elbow flexion axis. These files have no ELB marker, so the forearm carries only ULNA (ulnar
styloid) and RADIUS (radial styloid): no forearm pose without borrowing markers. Two estimates:
* "path" (primary): the path of ULNA in the humerus frame (path_axis). The ulnar styloid lies on
  the pronation-supination axis (radial head to ulnar styloid), so pronation barely moves it: its
  path is a circle about the flexion axis. Limitation: one point, so the circle centre (the point
  on the axis) needs a wide arc (>= 60 deg, see exubio.calibration.functional).
* SARA between the humerus and a forearm pseudo-cluster ULNA, RADIUS, EPI_lat, EPI_med: the
  epicondyles sit near the flexion axis and so move little relative to the forearm too, but the
  pseudo-cluster is not rigid (RADIUS pronates about ULNA, the epicondyles are not exactly on the
  axis): reported as limited, with its off-axis rotation.
Both are compared with the transepicondylar line (EPI_lat -> EPI_med) and the EPI midpoint.

A check that fails (InputError) is printed as REJECTED, then the fit is repeated with the checks
off and its figures printed as UNTRUSTED. Figures only; this is not a test.

Usage: python studies/functional_joints_real.py [--json]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from exubio.calibration.cluster import cluster_poses
from exubio.calibration.functional import FunctionalAxis, FunctionalCentre, path_axis, sara, score
from exubio.errors import InputError
from exubio.io.trial import read_trial
from exubio.prep.thorax import thorax_frame

ROOT = Path(__file__).resolve().parents[1]
C3D = ROOT.parent / "shared" / "data" / "c3d"
TRIALS = [
    ("bioptim_exo_martin_dynamique.c3d", False),
    ("bioptim_exo_kinova_martin_dent_f3_1.c3d", True),  # True: RADIUS/ULNA swapped in that session
]
SCAPULA = ("SCAP_AC", "SCAP_BACK", "SCAP_FRONT")
THORAX = ("MAN", "XYP", "C7", "T10")
HUMERUS = ("ARM", "DELT", "EPI_lat", "EPI_med")
FOREARM_PSEUDO = ("ULNA", "RADIUS", "EPI_lat", "EPI_med")


def _mm(v) -> str:
    return "(" + ", ".join(f"{1e3 * x:7.1f}" for x in v) + ") mm"


def _unit(v) -> str:
    return "(" + ", ".join(f"{x:6.3f}" for x in v) + ")"


class Trial:
    def __init__(self, path: Path, swap_forearm: bool):
        traj = read_trial(path)
        labels = list(traj.labels)
        if swap_forearm:
            i, j = labels.index("ULNA"), labels.index("RADIUS")
            labels[i], labels[j] = labels[j], labels[i]
        self.labels = labels
        self.pos = traj.positions_m
        self.n = self.pos.shape[0]
        self.rate = traj.rate_hz
        missing = [m for m in SCAPULA + THORAX + HUMERUS + FOREARM_PSEUDO if m not in labels]
        if missing:
            raise InputError(f"{path.name}: markers {missing} are missing")
        # first frame with every marker used here: the reference frame of all clusters
        needed = self.markers(*(SCAPULA + THORAX + HUMERUS + FOREARM_PSEUDO))
        complete = np.flatnonzero(np.isfinite(needed).all(axis=(1, 2)))
        if complete.size == 0:
            raise InputError(f"{path.name}: no frame has every marker")
        self.f0 = int(complete[0])
        # ISB thorax frame in every frame (columns X, Y, Z in lab coordinates), origin MAN
        man, xyp, c7, t10 = (self.markers(m)[:, 0] for m in THORAX)
        self.thorax_R, self.thorax_o = thorax_frame(man, xyp, c7, t10)

    def markers(self, *names: str) -> np.ndarray:
        return self.pos[:, [self.labels.index(n) for n in names]]

    def to_thorax(self, p_lab: np.ndarray, frame: int) -> np.ndarray:
        return self.thorax_R[frame].T @ (p_lab - self.thorax_o[frame])

    def segment(self, names: tuple[str, ...], frame_R: np.ndarray, frame_o: np.ndarray):
        """Poses of a cluster whose local frame is (frame_R columns, frame_o) at the first frame."""
        m = self.markers(*names)
        ref = (m[self.f0] - frame_o) @ frame_R  # reference shape in that frame
        R, t, rms = cluster_poses(ref, m)
        return R, t, rms, ref


def scapula_frame(trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    ac, back, front = trial.markers(*SCAPULA)[trial.f0]
    x = front - back
    x /= np.linalg.norm(x)
    z = np.cross(x, ac - back)
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1), ac


def _fit(kind: str, fn, *args, **relaxed):
    """Run with the default checks; on InputError print it and rerun with the checks off."""
    try:
        return fn(*args), True
    except InputError as err:
        print(f"    REJECTED: {err}")
        return fn(*args, **relaxed), False


def _score_lines(tag: str, res: FunctionalCentre, trusted: bool) -> None:
    if not trusted:
        print("    UNTRUSTED: the figures below are with the checks off")
    print(f"    RMS mismatch {1e3 * res.rms_m:.1f} mm (max {1e3 * res.max_mismatch_m:.1f} mm); relative rotation "
          f"range {res.rotation_range_deg:.1f} deg, off-axis spread {res.spread_deg:.1f} deg "
          f"(s_min/s_max {res.condition:.3g}); frames used {res.n_frames_used}, skipped {res.n_frames_skipped}")


def _autocorrelation_time(res: np.ndarray) -> float:
    """Integrated autocorrelation time (frames) of (n, 3) residuals, summed up to the first
    non-positive lag: 1 for white residuals, larger for slowly varying skin artefacts."""
    r = res - res.mean(axis=0)
    var = float(np.sum(r * r))
    tau = 1.0
    for k in range(1, r.shape[0] // 2):
        rho = float(np.sum(r[k:] * r[:-k])) / var
        if rho <= 0:
            break
        tau += 2.0 * rho
    return tau


def _weak_se(seg1, seg2, res: FunctionalCentre) -> tuple[float, float]:
    """Approximate standard error (m) of the fitted (c1, c2) along the least-determined direction:
    sigma / s_min for white residuals, inflated by sqrt(autocorrelation time). Diagnostic only."""
    ok = np.isfinite(res.centre_global).all(axis=1)
    r = (np.einsum("nab,b->na", seg1[0][ok], res.centre_local1) + seg1[1][ok]
         - np.einsum("nab,b->na", seg2[0][ok], res.centre_local2) - seg2[1][ok])
    sigma = math.sqrt(float(np.sum(r ** 2)) / (r.size - 6))
    tau = _autocorrelation_time(r)
    return sigma * math.sqrt(tau) / float(res.singular_values[-1]), tau


def gh(trial: Trial, out: list[dict]) -> None:
    f0 = trial.f0
    Rs, os_ = scapula_frame(trial)
    scap = trial.segment(SCAPULA, Rs, os_)
    thor = trial.segment(THORAX, trial.thorax_R[f0], trial.thorax_o[f0])
    hum_m = trial.markers(*HUMERUS)
    hum_ref = hum_m[f0] - hum_m[f0].mean(axis=0)  # humerus local frame: centroid, lab axes at f0
    hum = (*cluster_poses(hum_ref, hum_m), hum_ref)
    print(f"  cluster fit RMS, median (max) over frames: acromion {1e3 * np.nanmedian(scap[2]):.2f} "
          f"({1e3 * np.nanmax(scap[2]):.2f}) mm, thorax {1e3 * np.nanmedian(thor[2]):.2f} "
          f"({1e3 * np.nanmax(thor[2]):.2f}) mm, humerus {1e3 * np.nanmedian(hum[2]):.2f} "
          f"({1e3 * np.nanmax(hum[2]):.2f}) mm")
    ac = trial.markers("SCAP_AC")[:, 0]
    epi_mid = trial.markers("EPI_lat", "EPI_med").mean(axis=1)
    results = {}
    relaxed = dict(min_range_deg=0.0, min_spread_deg=0.0)
    for tag, seg1 in (("GH, SCoRE acromion cluster (1) vs humerus (2)", scap),
                      ("GH, SCoRE thorax (1) vs humerus (2), for comparison", thor)):
        print(f"  {tag}")
        res, trusted = _fit(tag, score, seg1[0], seg1[1], hum[0], hum[1], **relaxed)
        _score_lines(tag, res, trusted)
        c = res.centre_global
        used = np.flatnonzero(np.isfinite(c).all(axis=1))
        i0 = int(used[0])
        c_th = trial.to_thorax(c[i0], i0)
        d_ac = np.linalg.norm(c - ac, axis=1)
        d_epi = np.linalg.norm(c - epi_mid, axis=1)
        if seg1 is scap:
            print(f"    centre in the scapula cluster frame:          {_mm(res.centre_local1)}")
        else:
            print(f"    centre in the (fitted) thorax cluster frame:  {_mm(res.centre_local1)}")
        print(f"    centre in the humerus cluster frame:          {_mm(res.centre_local2)}  "
              f"(origin: cluster centroid, lab axes at frame {f0})")
        print(f"    centre in the ISB thorax frame at frame {i0}:    {_mm(c_th)}")
        print(f"    distance from SCAP_AC: {1e3 * d_ac[i0]:.1f} mm at frame {i0} "
              f"(median {1e3 * np.nanmedian(d_ac):.1f}, "
              f"range {1e3 * np.nanmin(d_ac):.1f}-{1e3 * np.nanmax(d_ac):.1f})")
        print(f"    distance from the EPI midpoint: {1e3 * d_epi[i0]:.1f} mm at frame {i0} (median "
              f"{1e3 * np.nanmedian(d_epi):.1f}, range {1e3 * np.nanmin(d_epi):.1f}-{1e3 * np.nanmax(d_epi):.1f})")
        se, tau = _weak_se(seg1, hum, res)
        print(f"    approx. standard error along the least-determined direction: {1e3 * se:.1f} mm "
              f"(white-residual value x sqrt of the residual autocorrelation time, {tau:.0f} frames)")
        results[tag] = res
        out.append({"joint": "GH", "fit": tag, "trusted": trusted, **res.to_dict(),
                    "centre_thorax_first_frame_mm": [round(1e3 * x, 2) for x in c_th],
                    "distance_from_SCAP_AC_mm": round(1e3 * float(d_ac[i0]), 2),
                    "distance_from_EPI_mid_mm": round(1e3 * float(d_epi[i0]), 2),
                    "weak_direction_se_mm": round(1e3 * se, 2)})
    a, b = results.values()
    gap = np.linalg.norm(a.centre_global - b.centre_global, axis=1)
    print(f"  the two GH estimates differ by {1e3 * gap[f0]:.1f} mm at frame {f0} "
          f"(median {1e3 * np.nanmedian(gap):.1f} mm over frames)")
    # skin motion of ARM / DELT: the acromion-cluster fit with either one left out
    for subset in (("ARM", "EPI_lat", "EPI_med"), ("DELT", "EPI_lat", "EPI_med")):
        m = trial.markers(*subset)
        R, t, _ = cluster_poses(m[f0] - m[f0].mean(axis=0), m)
        res = score(scap[0], scap[1], R, t, min_range_deg=0.0, min_spread_deg=0.0)
        shift = np.linalg.norm(res.centre_global - a.centre_global, axis=1)
        print(f"  humerus cluster {'+'.join(subset)} instead (acromion vs humerus, checks off): RMS "
              f"{1e3 * res.rms_m:.1f} mm, centre moves by {1e3 * np.nanmedian(shift):.1f} mm (median over frames), "
              f"{1e3 * np.linalg.norm(res.centre_local1 - a.centre_local1):.1f} mm in the scapula cluster frame")
        out.append({"joint": "GH", "fit": f"acromion vs {'+'.join(subset)} (checks off)", **res.to_dict(),
                    "shift_from_4_marker_fit_mm": round(1e3 * float(np.nanmedian(shift)), 2)})


def _axis_report(trial: Trial, tag: str, res: FunctionalAxis, trusted: bool, hum_R, hum_t,
                 out: list[dict]) -> np.ndarray:
    if not trusted:
        print("    UNTRUSTED: the figures below are with the checks off")
    extra = ("" if math.isnan(res.off_axis_rms_deg) else f", off-axis rotation {res.off_axis_rms_deg:.1f} deg rms")
    print(f"    range about the axis {res.range_deg:.1f} deg{extra}; condition {res.condition:.3g}; residual RMS "
          f"{1e3 * res.rms_m:.1f} mm, {res.direction_rms_deg:.1f} deg; frames used {res.n_frames_used}, "
          f"skipped {res.n_frames_skipped}")
    # axis and epicondyles in the humerus frame (median over frames of the EPI positions there)
    epi = trial.markers("EPI_lat", "EPI_med")
    epi_local = np.einsum("nji,nkj->nki", hum_R, epi - hum_t[:, None, :])
    lat, med = np.nanmedian(epi_local, axis=0)
    tea = (med - lat) / np.linalg.norm(med - lat)
    mid = 0.5 * (lat + med)
    a, p = res.direction_local1, res.point_local1
    angle = math.degrees(math.acos(min(1.0, abs(float(a @ tea)))))
    d = mid - p
    dist = float(np.linalg.norm(d - (d @ a) * a))
    f0 = trial.f0
    if a @ tea > 0:  # shown pointing laterally, from EPI_med towards EPI_lat (ISB: +Z, to the right)
        a = -a
    a_th = trial.thorax_R[f0].T @ (hum_R[f0] @ a)
    print(f"    direction (medial to lateral) at frame {f0} in the ISB thorax frame {_unit(a_th)}; "
          f"angle to the transepicondylar line {angle:.1f} deg; axis to EPI midpoint {1e3 * dist:.1f} mm")
    out.append({"joint": "elbow", "fit": tag, "trusted": trusted, **res.to_dict(),
                "angle_to_transepicondylar_deg": round(angle, 2), "distance_from_EPI_mid_mm": round(1e3 * dist, 2)})
    return a


def elbow(trial: Trial, out: list[dict]) -> None:
    f0 = trial.f0
    hum_m = trial.markers(*HUMERUS)
    hum_ref = hum_m[f0] - hum_m[f0].mean(axis=0)
    hum_R, hum_t, _ = cluster_poses(hum_ref, hum_m)
    ulna = trial.markers("ULNA")[:, 0]
    ulna_local = np.einsum("nji,nj->ni", hum_R, ulna - hum_t)
    tag = "elbow flexion, path of ULNA in the humerus frame (pronation-free)"
    print(f"  {tag}")
    res, ok = _fit(tag, path_axis, ulna_local, min_range_deg=0.0, max_condition=math.inf)
    a_path = _axis_report(trial, tag, res, ok, hum_R, hum_t, out)
    fa_m = trial.markers(*FOREARM_PSEUDO)
    fa_ref = fa_m[f0] - fa_m[f0].mean(axis=0)
    fa_R, fa_t, fa_rms = cluster_poses(fa_ref, fa_m)
    tag = "elbow flexion, SARA humerus vs ULNA+RADIUS+EPI pseudo-cluster (limited: not rigid)"
    print(f"  {tag}")
    print(f"    pseudo-cluster fit RMS median {1e3 * np.nanmedian(fa_rms):.1f} mm "
          f"(max {1e3 * np.nanmax(fa_rms):.1f} mm)")
    res, ok = _fit(tag, sara, hum_R, hum_t, fa_R, fa_t, min_range_deg=0.0, max_condition=math.inf)
    a_sara = _axis_report(trial, tag, res, ok, hum_R, hum_t, out)
    between = math.degrees(math.acos(min(1.0, abs(float(a_path @ a_sara)))))
    print(f"  angle between the two elbow axes: {between:.1f} deg")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="also print one JSON line per fit")
    args = ap.parse_args(argv)
    print("Data: Ipuch/bioptim_exo @ b4a33b4e (MIT, Copyright (c) 2022 Pierre), see ../shared/data/SOURCES.md")
    ran = 0
    for name, swap in TRIALS:
        path = C3D / name
        print(f"\n== {name}" + ("  (RADIUS/ULNA swapped back, kinova_martin session)" if swap else ""))
        if not path.is_file():
            print(f"  skipped: {path} is absent")
            continue
        trial = Trial(path, swap)
        print(f"  {trial.n} frames at {trial.rate:g} Hz; cluster reference frame {trial.f0}")
        out: list[dict] = []
        gh(trial, out)
        elbow(trial, out)
        if args.json:
            for row in out:
                print(json.dumps({"trial": name, **row}))
        ran += 1
    if ran == 0:
        print("no trial found: nothing to report", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
