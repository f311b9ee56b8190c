"""Simulated marker trials with a known true motion: arm abduction, arm flexion and the paper's
simulated internal-external rotation (SIER), with optional measurement noise and soft-tissue
artefact (STA).

True motion
-----------
Eleven coordinates are prescribed as analytic functions of time (so their q̇ and q̈ are exact);
``ac_protraction`` and ``ac_upward_rotation`` are solved in every frame so that the two scapula
points stay on the thorax ellipsoid (|g| < 1e-12: Newton on g with the analytic G, all frames at
once, warm-started from the calibration grid below). Their rates follow from implicit
differentiation of g(q) = 0: G q̇ = 0 and G q̈ + eta = 0. (That pair, rather than ac_protraction
and ac_posterior_tilt, because with ac_upward_rotation prescribed the constraint solution folds
back -- no solution nearby -- at about 5 deg of AC upward rotation above 100 deg of flexion; with
ac_posterior_tilt prescribed the 2x2 block of G stays well conditioned, cond < 4, over -30..40 deg.)

* ABDUCTION / FLEXION: cycles (period 5 s) of humerothoracic (HT) elevation
  θ(t) = 10° + 110° (1 - cos 2πt/T) / 2, i.e. 10° -> 120° -> 10°, in the coronal plane (humerus
  rotated about thorax -X) or the sagittal plane (about +Z), with a modest humeral axial rotation
  (external, 20° resp. 10° at the top). The clavicle and scapula follow the scapulohumeral rhythm
  of Ludewig et al. 2009 (table ``LUDEWIG_2009`` below): the changes of the SC and ST angles
  relative to the lowest tabulated elevation (30°), extrapolated linearly below 30° with the
  30->45° slope and shifted to be zero at 0° (the model's reference posture, arm hanging),
  interpolated with a natural cubic spline over HT elevation (C2). The SC changes are applied to
  the ISB clavicle frame (Y-X'-Z'' from the model's reference SC angles) and expressed in the
  model's SC coordinates (``sc_in_isb_frame``), so the simulated ISB SC angles change as
  Ludewig's do. The scapula has one rotation left once the
  clavicle and the two ellipsoid constraints are set; it is chosen (through ac_posterior_tilt,
  fitted on a 5° grid and splined over θ) so that the changes of the ISB scapulothoracic angles
  (``scapula_isb_angles``: ISB scapula frame from AA, TS, AI; Y-X'-Z'') are as close as possible,
  in least squares, to Ludewig's ST changes (internal rotation, upward rotation, tilt). With the
  generic model's ellipsoid the fit is partial: at 120° of abduction the scapula upward-rotates
  ~19° (Ludewig: 42°) and tilts posteriorly ~26° (18°); forcing Ludewig's full upward rotation
  would need more than 70° of posterior tilt, the inferior angle wrapping round to the front of
  the thorax. ``rhythm_table`` gives the fitted numbers. The GH coordinates follow from
  R_scapula^T R_humerus, and their rates from the (analytic) humerus and the scapula's angular
  velocities and accelerations (Kinematics.coordinate_rates). Elbow flexion goes 15° -> 40° with
  the elevation, pronation 40° ± 20° (from full supination, inside its range), wrist flexion ±10°
  and radial deviation ±8° (sinusoids), so
  every coordinate moves.
* SIER (paper, after Roux et al.): arm at 25° HT elevation in the coronal plane (clavicle and
  scapula on the same rhythm, constant), elbow flexed 90°, forearm and wrist at 0°, and
  gh_internal_rotation = its 25° value + 40° sin(2π 0.5 t) (12.5 cycles in 25 s).

Markers
-------
Model points of the same names (default: the 22 markers of ``DEFAULT_MARKERS``, the
upper_limb_21 protocol's 18 plus its thorax landmarks MAN, XYP, C7, T10), from
Kinematics.points. With ``lab_transform`` they are expressed in a lab frame (Z up, X forward,
thorax origin at ``LAB_ORIGIN_M``, thorax rotated ``LAB_YAW_DEG`` about the vertical):
p_lab = lab_origin_m + lab_rotation @ p_thorax, so a reader must rebuild the ISB thorax frame
from MAN/XYP/C7/T10 (exact in the model: midpoint(XYP, T10) -> midpoint(MAN, C7) is +Y).

Soft-tissue artefact (``sta_mm``)
--------------------------------
After Dumas et al. 2014 and the paper's adaptation of Roux et al.: every non-thorax marker k on
segment s gets a displacement fixed in that segment's frame,

    d_k(t) = R_s(t) · (A_s · u_k · f_k(t)),   f_k(t) = c_k · (q(t) - q(0)) / max_t |c_k · (q(t) - q(0))|

with u_k a random unit direction per marker, c_k random N(0, 1) weights over the coordinates of
the segment's own (proximal) joint and of the joint just distal to it (so the artefact is
motion-dependent and smooth, zero in the first frame, and |f_k| reaches exactly 1 during the
trial), and A_s = sta_mm × (humerus 1.0, scapula 0.6, clavicle 0.3, ulna/radius/hand 0.25). Each
humerus marker's artefact therefore peaks at exactly ``sta_mm`` (the paper's artefact reached
~20 mm on its GH marker). A marker whose driving coordinates do not move gets no artefact
(in SIER: forearm and hand). Thorax markers get no artefact. With ``sta_model`` (a bone STA model
fitted on bone-pin data, exubio.synth.sta_bone / sta_sim) the scapula and humerus markers instead move
as that model predicts from the simulated angles (the regression's mean course, plus a draw of its
held-out residual from the stream ``SeedSequence([seed, 33])``); the other segments keep the
per-marker artefact.

Noise (``noise_mm``): independent Gaussian, SD ``noise_mm`` per coordinate and sample, on every
marker (thorax markers included). STA and noise use independent seeded streams
(``numpy.random.SeedSequence(seed).spawn(2)``); ``sta_m`` and ``noise_m`` are stored in the same
frame as the trajectories (lab frame when ``lab_transform``), trajectories = points + sta + noise.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from exubio.errors import InputError
from exubio.model.kinematics import Kinematics, axis_rotation
from exubio.synth.perturb import ModelPerturbation
from exubio.synth.rhythm import (FITTED, FREE, PLANE_OF, RHYTHM_MAP, RHYTHM_TABLE_COLUMNS,
                                 SCAPULAR_PLANE_DEG, girdle_calibration, rhythm_splines,
                                 sc_in_isb_frame, solve_free)
from exubio.types import Model, Trajectories

__all__ = [
    "DEFAULT_MARKERS",
    "Motion",
    "SimulatedTrial",
    "rhythm_table",
    "simulate_trial",
    "write_simulated_trial",
]

DEFAULT_MARKERS: tuple[str, ...] = (
    "MAN", "XYP", "C7", "T10",
    "CLAV_SC", "CLAV_AC",
    "SCAP_Cor", "SCAP_AA", "SCAP_AC", "SCAP_IA", "SCAP_BACK", "SCAP_FRONT",
    "ARM", "DELT", "EPI_lat", "EPI_med",
    "ULNA", "ELB", "RADIUS",
    "MET2", "MET5", "SEML",
)  # fmt: skip
STA_SCALE = {"thorax": 0.0, "clavicle": 0.3, "scapula": 0.6, "humerus": 1.0, "ulna": 0.25, "radius": 0.25, "hand": 0.25}
LAB_ORIGIN_M = np.array([0.3, 0.5, 1.4])
LAB_YAW_DEG = 20.0

CYCLE_S = 5.0
ELEVATION_RANGE_DEG = (10.0, 120.0)
SIER_ELEVATION_DEG = 25.0
SIER_AMPLITUDE_DEG = 40.0
SIER_FREQUENCY_HZ = 0.5
SIER_ELBOW_DEG = 90.0
PRONATION_MEAN_DEG = 40.0  # forearm midway from full supination (the reference posture): inside its range


class Motion(str, enum.Enum):
    ABDUCTION = "abduction"  # coronal-plane elevation cycles
    FLEXION = "flexion"  # sagittal-plane elevation cycles
    SCAPTION = "scaption"  # scapular-plane elevation cycles (40 deg anterior to the coronal plane)
    SIER = "sier"  # simulated internal-external rotation (paper)

    @classmethod
    def parse(cls, value: "Motion | str") -> "Motion":
        """A Motion from itself or its name (case-insensitive, 'abduction', 'flexion', 'scaption', 'sier')."""
        if isinstance(value, cls):
            return value
        text = str(value).strip().lower().replace("-", "_")
        for m in cls:
            if text in (m.value, m.name.lower()):
                return m
        raise InputError(f"unknown motion '{value}'; valid motions are {[m.value for m in cls]}")


@dataclass(frozen=True)
class SimulatedTrial:
    """A simulated trial and its truth.

    trajectories: markers (metres) in the lab frame (or the thorax frame without lab_transform).
    q_true, qd_true, qdd_true: (n, 13) rad, rad/s, rad/s^2 (exact: analytic + implicit).
    sta_m, noise_m: (n, k, 3) the added artefact and noise, in the trajectories' frame.
    lab_rotation, lab_origin_m: p_lab = lab_origin_m + lab_rotation @ p_thorax (identity, zero
    without lab_transform). marker_segments: the segment of each marker.
    """

    trajectories: Trajectories
    time_s: np.ndarray
    q_true: np.ndarray
    qd_true: np.ndarray
    qdd_true: np.ndarray
    coordinate_names: tuple[str, ...]
    sta_m: np.ndarray
    noise_m: np.ndarray
    description: str
    motion: Motion = Motion.ABDUCTION
    lab_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    lab_origin_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    marker_segments: tuple[str, ...] = ()
    perturbation: ModelPerturbation | None = None  # the model was perturbed by this before generating
    model: Model | None = None  # the model the trial was generated with (perturbed, if so)
    sta_model: str = "per-marker"  # the STA model: "per-marker", or a bone model's line (exubio.synth.sta_sim)
    thorax_motion: object = None  # exact ThoraxMotion in the lab of a leaning trunk (exubio.synth.thorax_lean), or None


# --------------------------------------------------------------------------------------------
# Analytic signals: c0 + sum a sin(w t + phi)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Signal:
    c0: float
    terms: tuple[tuple[float, float, float], ...] = ()  # (amplitude, omega rad/s, phase)

    def eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = np.full_like(t, self.c0, dtype=float)
        xd = np.zeros_like(x)
        xdd = np.zeros_like(x)
        for a, w, ph in self.terms:
            arg = w * t + ph
            x += a * np.sin(arg)
            xd += a * w * np.cos(arg)
            xdd -= a * w * w * np.sin(arg)
        return x, xd, xdd


def elevation_axis(motion: Motion) -> np.ndarray:
    """The thorax-frame axis the humerus is elevated about: -X (coronal), +Z (sagittal), and for
    the scapular plane the axis of the plane SCAPULAR_PLANE_DEG anterior to the coronal one."""
    if motion is Motion.FLEXION:
        return np.array([0.0, 0.0, 1.0])
    if motion is Motion.SCAPTION:
        a = np.radians(SCAPULAR_PLANE_DEG)
        return np.array([-np.cos(a), 0.0, np.sin(a)])
    return np.array([-1.0, 0.0, 0.0])


def _cycle(low: float, high: float, w: float) -> _Signal:
    """low + (high - low) (1 - cos w t) / 2 (radians)."""
    return _Signal(0.5 * (low + high), ((-0.5 * (high - low), w, 0.5 * np.pi),))


def rhythm_table(model: Model, motion: Motion | str = Motion.ABDUCTION, /) -> tuple[tuple[str, ...], np.ndarray]:
    """The shoulder-girdle rhythm the simulation uses for ``motion`` (SIER: the abduction one),
    every 5 deg of HT elevation from 0 to 120: (RHYTHM_TABLE_COLUMNS, (25, 13) array in degrees).
    ``*_st_*`` are changes from 0 deg of the ISB scapulothoracic angles (``scapula_isb_angles``;
    X negative = upward rotation) of the model and of Ludewig et al. 2009."""
    kin = Kinematics(model)
    plane = PLANE_OF[Motion.parse(motion).value]
    free = np.array([model.coordinate_names.index(c) for c in FREE])
    return RHYTHM_TABLE_COLUMNS, girdle_calibration(kin, sc_in_isb_frame(kin, rhythm_splines(plane)), free)[3]


def _segment_angular_accelerations(kin: Kinematics, fr, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Global angular acceleration of every segment (..., n_seg, 3)."""
    wq = fr.axes * qd[..., None]
    frame_rate = np.einsum("jk,...kc->...jc", kin.precedes.astype(float), wq)
    wdot = np.cross(frame_rate, fr.axes)
    per_coord = fr.axes * qdd[..., None] + wdot * qd[..., None]
    return np.einsum("sm,...mc->...sc", kin.affects.astype(float), per_coord)


# --------------------------------------------------------------------------------------------
# The trial
# --------------------------------------------------------------------------------------------
def _marker_points(kin: Kinematics, names: Sequence[str]):
    model = kin.model
    items, segs = [], []
    for name in names:
        seg = next((s for s in model.segments if name in s.points), None)
        if seg is None:
            known = sorted({p for s in model.segments for p in s.points})
            raise InputError(f"marker '{name}' is not a point of model '{model.name}'; its points are {known}")
        items.append((seg.name, name))
        segs.append(seg.name)
    return kin.point_set(items), tuple(segs)


def _lab_transform() -> tuple[np.ndarray, np.ndarray]:
    base = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # columns: thorax X, Y, Z in lab
    yaw = axis_rotation(np.array([0.0, 0.0, 1.0]), np.radians(LAB_YAW_DEG))
    return yaw @ base, LAB_ORIGIN_M.copy()


def _true_motion(kin: Kinematics, motion: Motion, t: np.ndarray, cycle_s: float = CYCLE_S):
    model = kin.model
    names = model.coordinate_names
    ix = {c: names.index(c) for c in names}
    n, m = t.size, len(names)
    q, qd, qdd = np.zeros((n, m)), np.zeros((n, m)), np.zeros((n, m))
    free = np.array([ix[c] for c in FREE])
    w = 2.0 * np.pi / cycle_s  # every moving coordinate's rate scales with it (a fast cycle: a fast motion)
    plane = PLANE_OF[motion.value]
    splines = sc_in_isb_frame(kin, rhythm_splines(plane))
    fit_spline, f0_spline, f1_spline, _ = girdle_calibration(kin, splines, free)
    d = np.radians

    if motion is Motion.SIER:
        th, thd, thdd = np.full(n, d(SIER_ELEVATION_DEG)), np.zeros(n), np.zeros(n)
        psi = psid = psidd = np.zeros(n)
        elev_axis = np.array([-1.0, 0.0, 0.0])
    else:
        th, thd, thdd = _cycle(d(ELEVATION_RANGE_DEG[0]), d(ELEVATION_RANGE_DEG[1]), w).eval(t)
        ext = d(10.0) if motion is Motion.FLEXION else d(20.0)
        psi, psid, psidd = _cycle(0.0, -ext, w).eval(t)  # external axial rotation with elevation
        elev_axis = elevation_axis(motion)

    # shoulder girdle: rhythm splines of theta(t), chain rule
    for c, sp in [(c, splines[c]) for c in RHYTHM_MAP] + [(FITTED, fit_spline)]:
        j = ix[c]
        d1, d2 = sp(th, 1), sp(th, 2)
        q[:, j], qd[:, j], qdd[:, j] = sp(th), d1 * thd, d2 * thd**2 + d1 * thdd
    q[:, free[0]], q[:, free[1]] = f0_spline(th), f1_spline(th)
    solve_free(kin, q, free)
    G = kin.G(q)
    Gs = G[..., free]
    qd[:, free] = np.linalg.solve(Gs, -np.einsum("nkm,nm->nk", G, qd)[..., None])[..., 0]
    rhs = kin.eta(q, qd) + np.einsum("nkm,nm->nk", G, qdd)
    qdd[:, free] = np.linalg.solve(Gs, -rhs[..., None])[..., 0]

    # humerus relative to the scapula
    gh = np.array([ix[c] for c in model.segment("humerus").joint.coordinates])
    hi = model.segment_index("humerus")
    R_elev = axis_rotation(elev_axis, th)
    y = np.array([0.0, 1.0, 0.0])
    R_h = R_elev @ axis_rotation(y, psi)
    fr = kin.frames(q)
    R_all = fr.R.copy()
    R_all[:, hi] = R_h
    q[:, gh] = kin.coordinates_from_rotations(R_all)[:, gh]
    if motion is Motion.SIER:
        ir = ix["gh_internal_rotation"]
        x, xd, xdd = _Signal(0.0, ((d(SIER_AMPLITUDE_DEG), 2.0 * np.pi * SIER_FREQUENCY_HZ, 0.0),)).eval(t)
        q[:, ir] += x
        qd[:, ir], qdd[:, ir] = xd, xdd
    else:
        # humerus angular velocity/acceleration (analytic), scapula's from the girdle rates
        e_y = R_elev @ y
        omega_h = thd[:, None] * elev_axis + psid[:, None] * e_y
        alpha_h = thdd[:, None] * elev_axis + psidd[:, None] * e_y + (thd * psid)[:, None] * np.cross(elev_axis, e_y)
        fr = kin.frames(q)
        omega = kin.segment_angular_velocities(q, qd)
        alpha = _segment_angular_accelerations(kin, fr, qd, qdd)
        omega[:, hi], alpha[:, hi] = omega_h, alpha_h
        rates, accs = kin.coordinate_rates(q, omega, alpha)
        qd[:, gh], qdd[:, gh] = rates[:, gh], accs[:, gh]

    # elbow, forearm, wrist
    if motion is Motion.SIER:
        distal = {"elbow_flexion": _Signal(d(SIER_ELBOW_DEG))}
    else:
        distal = {
            "elbow_flexion": _cycle(d(15.0), d(40.0), w),
            "pronation": _Signal(d(PRONATION_MEAN_DEG), ((d(20.0), w, 0.0),)),
            "wrist_flexion": _Signal(0.0, ((d(10.0), w, 0.5),)),
            "wrist_radial_deviation": _Signal(0.0, ((d(8.0), 2.0 * w, 0.0),)),
        }
    for c, sig in distal.items():
        q[:, ix[c]], qd[:, ix[c]], qdd[:, ix[c]] = sig.eval(t)
    return q, qd, qdd


def _sta(kin: Kinematics, q: np.ndarray, R_seg: np.ndarray, points, segs: Sequence[str], sta_m: float,
         rng: np.random.Generator) -> np.ndarray:
    """Soft-tissue artefact (n, k, 3) in the thorax frame (see the module docstring)."""
    model = kin.model
    n, k = q.shape[0], len(segs)
    out = np.zeros((n, k, 3))
    dq = q - q[:1]
    coord_idx = {}
    for s in model.segments:
        own = [model.coordinate_names.index(c) for c in (s.joint.coordinates if s.joint else ())]
        child = [model.coordinate_names.index(c) for ch in model.segments if ch.parent == s.name for c in ch.joint.coordinates]
        coord_idx[s.name] = np.array(own + child, dtype=int)
    for i, seg in enumerate(segs):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        idx = coord_idx[seg]
        weights = rng.normal(size=idx.size)
        amp = STA_SCALE.get(seg, 0.25) * sta_m
        if amp == 0.0 or idx.size == 0:
            continue
        s = dq[:, idx] @ weights
        peak = np.max(np.abs(s))
        if peak < 1e-12:
            continue
        local = amp * (s / peak)[:, None] * direction
        out[:, i] = np.einsum("nij,nj->ni", R_seg[:, points.segment_index[i]], local)
    return out


def simulate_trial(
    model: Model,
    motion: Motion | str,
    /,
    *,
    duration_s: float = 10.0,
    rate_hz: float = 100.0,
    noise_mm: float = 0.0,
    sta_mm: float = 0.0,
    seed: int = 0,
    marker_names: Sequence[str] | None = None,
    lab_transform: bool = True,
    perturbation: ModelPerturbation | None = None,
    sta_model=None,
    cycle_s: float = CYCLE_S,
    thorax_lean=None,
) -> SimulatedTrial:
    """Simulate a trial of ``motion`` on ``model`` (see the module docstring); with
    ``perturbation``, on ``perturbation.apply(model)`` (exubio.synth.perturb: a model mismatch for a
    reconstruction with ``model``; the truth is the perturbed model's coordinates). ``sta_model``:
    None or "per-marker" (the artefact above), or a bone STA model (a shipped name such as "bone",
    a JSON path, a BoneStaModel; exubio.synth.sta_sim) for the scapula and humerus markers.
    ``cycle_s``: the period of the elevation cycles (default CYCLE_S, a slow raise; 0.6 s makes a
    fast one, peak angular accelerations of thousands of deg/s^2). ``thorax_lean``: a
    exubio.synth.thorax_lean.ThoraxLean: the thorax leans in the lab in step with the raise (the
    arm's thorax-relative motion unchanged; its exact motion in ``thorax_motion``)."""
    from exubio.synth.sta_sim import resolve_sta_model

    bone = resolve_sta_model(sta_model)
    motion = Motion.parse(motion)
    if perturbation is not None:
        model = perturbation.apply(model)
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise InputError(f"duration must be > 0 s, got {duration_s}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"sampling rate must be > 0 Hz, got {rate_hz}")
    if not (np.isfinite(cycle_s) and cycle_s > 0):
        raise InputError(f"--cycle-s must be > 0 s, got {cycle_s}")
    if not (noise_mm >= 0 and sta_mm >= 0):
        raise InputError(f"noise_mm and sta_mm must be >= 0, got {noise_mm} and {sta_mm}")
    names = tuple(DEFAULT_MARKERS if marker_names is None else marker_names)
    if not names or len(set(names)) != len(names):
        raise InputError(f"marker names must be non-empty and unique, got {list(names)}")
    n = int(round(duration_s * rate_hz))
    if n < 2:
        raise InputError(f"{duration_s} s at {rate_hz} Hz gives fewer than 2 frames")
    kin = Kinematics(model)
    points, segs = _marker_points(kin, names)
    t = np.arange(n) / rate_hz

    q, qd, qdd = _true_motion(kin, motion, t, cycle_s)
    fr = kin.frames(q)
    pos = kin.points(q, points, frames=fr)

    sta_ss, noise_ss = np.random.SeedSequence(seed).spawn(2)
    sta = _sta(kin, q, fr.R, points, segs, sta_mm * 1e-3, np.random.default_rng(sta_ss))
    sta_label = "per-marker"
    if bone is not None:
        from exubio.synth.sta_sim import apply_bone_sta, describe

        sta, replaced, _ = apply_bone_sta(model, kin, q, fr.R, pos, segs, bone, sta,
                                          np.random.default_rng(sta_ss.spawn(1)[0]), rate_hz=float(rate_hz),
                                          residual_rng=np.random.default_rng(np.random.SeedSequence([seed, 33])))
        sta_label = describe(bone, replaced, sta_mm)
    if lab_transform:
        rot, origin = _lab_transform()
    else:
        rot, origin = np.eye(3), np.zeros(3)
    thorax_motion = None
    if thorax_lean is not None:
        from exubio.synth.thorax_lean import lean_motion, thorax_skin_artefact

        sta = sta + thorax_skin_artefact(thorax_lean, t, cycle_s, segs,
                                         np.random.default_rng(np.random.SeedSequence([seed, 36])))
        thorax_motion = lean_motion(thorax_lean, t, cycle_s, rot, origin)
        R_t = thorax_motion.rotation
        pos = np.einsum("nij,nkj->nki", R_t, pos) + thorax_motion.origin_m[:, None, :]
        sta = np.einsum("nij,nkj->nki", R_t, sta)
    else:
        pos = pos @ rot.T + origin
        sta = sta @ rot.T
    noise = (np.random.default_rng(noise_ss).normal(0.0, noise_mm * 1e-3, size=pos.shape)
             if noise_mm > 0 else np.zeros_like(pos))
    traj = Trajectories(labels=names, positions_m=pos + sta + noise, rate_hz=float(rate_hz), time_s=t,
                        source=f"simulated:{motion.value}", units_in_file="m")

    if motion is Motion.SIER:
        what = (f"simulated internal-external rotation: gh_internal_rotation ±{SIER_AMPLITUDE_DEG:g} deg at "
                f"{SIER_FREQUENCY_HZ:g} Hz, HT elevation {SIER_ELEVATION_DEG:g} deg, elbow {SIER_ELBOW_DEG:g} deg")
    else:
        plane = "coronal" if motion is Motion.ABDUCTION else "sagittal"
        what = (f"simulated {motion.value}: {duration_s / cycle_s:g} cycle(s) of {cycle_s:g} s, HT elevation "
                f"{ELEVATION_RANGE_DEG[0]:g}-{ELEVATION_RANGE_DEG[1]:g} deg in the {plane} plane, "
                f"Ludewig et al. 2009 scapulohumeral rhythm")
    desc = (f"{what}; {n} frames at {rate_hz:g} Hz; noise SD {noise_mm:g} mm; STA {sta_mm:g} mm (humerus peak); "
            f"seed {seed}; {'lab' if lab_transform else 'thorax'} frame; model {model.name}")
    if bone is not None:
        desc += f"; STA: {sta_label}"
    if thorax_lean is not None:
        desc += f"; {thorax_lean.describe()}"
    return SimulatedTrial(trajectories=traj, time_s=t, q_true=q, qd_true=qd, qdd_true=qdd,
                          coordinate_names=model.coordinate_names, sta_m=sta, noise_m=noise, description=desc,
                          motion=motion, lab_rotation=rot, lab_origin_m=origin, marker_segments=segs,
                          perturbation=perturbation, model=model, sta_model=sta_label, thorax_motion=thorax_motion)


def write_simulated_trial(trial: SimulatedTrial, path_c3d, /) -> tuple[Path, Path]:
    """Write ``PATH.c3d`` (markers, mm) and ``PATH.truth.csv`` (time_s + every coordinate in
    degrees; a perturbed trial's header states its perturbation, ``ModelPerturbation.from_header``).
    ``path_c3d`` may end in .c3d or not. Returns (c3d path, truth csv path)."""
    from exubio.io.c3d import write_c3d
    from exubio.io.results import write_angles_csv

    p = Path(path_c3d)
    stem = p.with_suffix("") if p.suffix.lower() == ".c3d" else p
    c3d_path = stem.with_name(stem.name + ".c3d")
    csv_path = stem.with_name(stem.name + ".truth.csv")
    write_c3d(c3d_path, trial.trajectories, units="mm")
    head = trial.perturbation.header_lines() if trial.perturbation is not None else ()
    if trial.sta_model != "per-marker":
        head = (*head, f"soft-tissue artefact: {trial.sta_model}")
    write_angles_csv(csv_path, trial.time_s, trial.coordinate_names, trial.q_true, comments=head)
    return c3d_path, csv_path


def reference_postures(model: Model, /, *, per_plane: int = 8, kinematics: Kinematics | None = None) -> np.ndarray:
    """Postures (3 * per_plane, m) of the simulated elevations in the coronal, scapular and
    sagittal planes (HT 10-120 deg, the girdle on Ludewig et al.'s rhythm, elbow, forearm and wrist
    moving as in the trials): the postures over which a marker set's structural determinacy is
    judged (exubio.trust.assess: what a protocol can measure, known before any trial); ``kinematics``:
    the model's, where the caller has it (exubio.protocol.bind.Binding.kin)."""
    kin = kinematics if kinematics is not None else Kinematics(model)
    t = np.linspace(0.0, CYCLE_S / 2.0, per_plane)
    return np.concatenate([_true_motion(kin, mo, t)[0] for mo in (Motion.ABDUCTION, Motion.SCAPTION, Motion.FLEXION)])
