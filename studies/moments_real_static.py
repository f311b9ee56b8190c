"""Joint moments of every real trial of ../shared/data (issue 36): the GH moment at a held posture
against the static estimate a hand computation gives from the segment masses and lever arms, and
the trials' peaks.

Each trial is reconstructed by LS as ``exubio reconstruct --method ls --body-mass 75`` does (the
shipped model and protocol; the kinova_martin session with its label fix,
protocols/examples/kinova_martin_session.yaml; the TRC trials with protocols/thoracoscapular_9.yaml),
and its moments computed with the thorax's motion measured from its markers (the TRC trials are
already thorax-fixed: thorax assumed still and upright).

Held posture: the 0.5 s window where the arm moves least (smallest mean |q'| over the humerus,
elbow, forearm and wrist coordinates), not within 0.25 s of either end of the trial (where the
filter's and the splines' end effects are). Static estimate, by hand (no Newton-Euler): with the
segments' masses m_s and centres of mass c_s (Dumas et al. 2007 scaled on the model), the GH centre
p and gravity g in the thorax frame (from the thorax's pose),

    M_static = sum over humerus, ulna, radius, hand of (c_s - p) x (-m_s g)

averaged over the window, against exubio's GH moment (its 3 ISB components, rotated back to the
thorax frame) averaged over the same window: the relative difference |M - M_static| / |M_static|.

    python studies/moments_real_static.py          # about a minute on 2 cores
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
SESSION = ROOT / "protocols" / "examples" / "kinova_martin_session.yaml"
TRC_PROTOCOL = ROOT / "protocols" / "thoracoscapular_9.yaml"
MASS_KG = 75.0
WINDOW_S = 0.5
ARM = ("humerus", "ulna", "radius", "hand")


def trials() -> list[tuple[Path, Path | None]]:
    c3d = sorted((SHARED / "c3d").glob("*.c3d"))
    out = [(p, SESSION if "kinova_martin" in p.name else None) for p in c3d]
    return out + [(p, TRC_PROTOCOL) for p in sorted((SHARED / "trc").glob("*.trc"))]


def held_window(model, qd: np.ndarray, rate_hz: float) -> slice:
    cols = [j for j, c in enumerate(model.coordinate_names)
            if model.segments[[s.name for s in model.segments].index(_segment_of(model, c))].name in ARM]
    speed = np.nanmean(np.abs(qd[:, cols]), axis=1)
    w = max(2, int(round(WINDOW_S * rate_hz)))
    mean = np.convolve(np.nan_to_num(speed, nan=1e9), np.ones(w) / w, mode="valid")
    edge = w // 2  # the first and last quarter second: the derivatives' end effects (filter, splines)
    mean[:edge] = mean[len(mean) - edge:] = np.inf
    k = int(np.argmin(mean))
    return slice(k, k + w)


def _segment_of(model, coordinate: str) -> str:
    return next(s.name for s in model.segments if s.joint and coordinate in s.joint.coordinates)


def static_estimate(model, q: np.ndarray, gravity_thorax: np.ndarray) -> np.ndarray:
    """(n, 3) thorax frame: the hand computation of the module docstring."""
    from exubio.dynamics.inertia import dynamics_model
    from exubio.model.kinematics import Kinematics

    dyn = dynamics_model(model)
    kin = Kinematics(dyn)
    fr = kin.frames(q)
    p = fr.p[:, dyn.segment_index("humerus")]
    total = np.zeros_like(p)
    for name in ARM:
        i = dyn.segment_index(name)
        seg = dyn.segments[i]
        c = fr.p[:, i] + np.einsum("nij,j->ni", fr.R[:, i], np.asarray(seg.com_m, dtype=float))
        total += np.cross(c - p, -seg.mass_kg * gravity_thorax)
    return total


def run_one(path: Path, protocol_path: Path | None) -> dict:
    from exubio.dynamics.inertia import isb_segment_frames
    from exubio.dynamics.moments import reconstruction_moments
    from exubio.dynamics.newton_euler import GRAVITY_M_S2
    from exubio.model.kinematics import Kinematics
    from exubio.prep.moment_options import MomentRequest
    from exubio.run.inputs import load_session
    from exubio.run.pipeline import load_inputs, reconstruct

    session = load_session(protocol_path=protocol_path, body_mass_kg=MASS_KG)
    inputs = load_inputs(path, session, moment_request=MomentRequest())
    model = inputs.model
    rec = reconstruct(model, inputs.protocol, inputs.targets, method="ls")
    thorax = inputs.moment_inputs.thorax
    mom = reconstruction_moments(model, rec, thorax=thorax)
    n = rec.q_rad.shape[0]
    g = np.tile(GRAVITY_M_S2, (n, 1)) if thorax is None else thorax.frame_terms().gravity
    win = held_window(model, rec.qd_rad_s, inputs.trial.rate_hz)
    # exubio's GH moment back in the thorax frame: M = R_h A m_isb
    A = isb_segment_frames(model)["humerus"][1]
    R = Kinematics(model).frames(rec.q_rad).R[:, model.segment_index("humerus")]
    m_isb = np.column_stack([mom.column(f"GH_{a}_moment_Nm") for a in "XYZ"])
    m = np.einsum("nij,jk,nk->ni", R, A, m_isb)
    est = static_estimate(model, rec.q_rad, g)
    m_w, e_w = np.nanmean(m[win], axis=0), np.nanmean(est[win], axis=0)
    gh = np.linalg.norm(m_isb, axis=1)
    return {"trial": path.name, "frames": n, "held_s": (rec.time_s[win.start], rec.time_s[win.stop - 1]),
            "M_Nm": float(np.linalg.norm(m_w)), "static_Nm": float(np.linalg.norm(e_w)),
            "rel": float(np.linalg.norm(m_w - e_w) / np.linalg.norm(e_w)),
            "peak_gh_Nm": float(np.nanmax(gh)), "peak_elbow_Nm": float(np.nanmax(np.abs(mom.column("elbow_flexion_moment_Nm")))),
            "thorax": "still (assumed)" if thorax is None else "measured",
            "lean_deg": float(np.nanmax(np.abs(np.degrees(_thorax_tilt(thorax))))) if thorax is not None else 0.0}


def _thorax_tilt(thorax):
    from exubio.dynamics.thorax_motion import thorax_angles

    a = thorax_angles(thorax)
    return a[:, :2] - np.nanmedian(a[:, :2], axis=0)


def main() -> int:
    logging.basicConfig(level=logging.ERROR)
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to measure")
        return 0
    rows = [run_one(p, proto) for p, proto in trials()]
    print(f"{'trial':48s} {'frames':>6s} {'held (s)':>13s} {'|M_GH| N m':>10s} {'static':>7s} {'diff %':>6s} "
          f"{'peak GH':>8s} {'peak elb':>8s} {'thorax':>16s} {'tilt dev':>8s}")
    for r in rows:
        print(f"{r['trial']:48s} {r['frames']:6d} {r['held_s'][0]:6.2f}-{r['held_s'][1]:5.2f} {r['M_Nm']:10.2f} "
              f"{r['static_Nm']:7.2f} {100 * r['rel']:6.2f} {r['peak_gh_Nm']:8.2f} {r['peak_elbow_Nm']:8.2f} "
              f"{r['thorax']:>16s} {r['lean_deg']:8.1f}")
    worst = max(r["rel"] for r in rows)
    print(f"worst difference from the static estimate at the held posture: {100 * worst:.2f} % (bound 10 %)")
    return 0 if worst < 0.10 else 1


if __name__ == "__main__":
    raise SystemExit(main())
