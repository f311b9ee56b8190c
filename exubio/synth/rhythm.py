"""The shoulder girdle on the published scapulohumeral rhythm: Ludewig et al. 2009's SC and ST
changes over humerothoracic elevation, put on the model's clavicle (``_sc_in_isb_frame``), and the
scapula held on the thorax ellipsoid with its one free rotation fitted to Ludewig's ST changes
(``girdle_calibration``). The simulated trials (exubio.synth.simulate) move the girdle on it; the
ellipsoid's calibration carries its postures (``rhythm_poses``). The method is described in
exubio.synth.simulate's docstring ("True motion")."""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from exubio.errors import ModelError
from exubio.literature.reference import ludewig2009_at
from exubio.model.kinematics import Kinematics
from exubio.types import Model

__all__ = ["FITTED", "FREE", "LUDEWIG_2009", "LUDEWIG_HT_DEG", "PLANE_OF", "RHYTHM_TABLE_COLUMNS", "SCAPULAR_PLANE_DEG",
           "RHYTHM_MAP", "ST_COLUMNS", "girdle_calibration", "rhythm_poses", "rhythm_splines", "sc_in_isb_frame", "scapula_isb_angles", "solve_free"]

# --------------------------------------------------------------------------------------------
# Published rhythm
# --------------------------------------------------------------------------------------------
# Ludewig PM, Phadke V, Braman JP, Hassett DR, Cieminski CJ, LaPrade RF (2009) Motion of the
# shoulder complex during multiplanar humeral elevation. J Bone Joint Surg Am 91(2):378-389,
# doi 10.2106/JBJS.G.01483 (bone pins, 12 shoulders, mean curves). Values as distributed by the
# Spartacus shoulder-kinematics dataset (Moissenet F, Puchaud P, Naaim A, Holzer N, Begon M
# (2024) Zenodo doi 10.5281/zenodo.11455521; spartacus/data/#11_Ludewig_et_al, commit ec0677c,
# "authors table"), every 15 deg of HT elevation. Degrees, in Ludewig's ISB frames (Y-X'-Z''):
# SC: Y + protraction, X - elevation, Z + posterior rotation; ST: Y + internal rotation,
# X - upward rotation, Z + posterior tilt.
LUDEWIG_HT_DEG = (30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0)
LUDEWIG_2009: dict[str, dict[str, tuple[float, ...]]] = ludewig2009_at(
    LUDEWIG_HT_DEG, ("SC_protraction", "SC_elevation", "SC_rotation", "ST_protraction", "ST_medRotation", "ST_tilt"),
    planes=("frontal", "scapular", "sagittal"))
# frontal = coronal-plane abduction, scapular = scapular-plane abduction (Ludewig: 40 deg anterior
# to the coronal plane), sagittal = flexion; read from exubio/data/ludewig2009.csv
SCAPULAR_PLANE_DEG = 40.0
PLANE_OF = {"abduction": "frontal", "scaption": "scapular", "flexion": "sagittal", "sier": "frontal"}
# model SC coordinate <- (Ludewig column, sign)
RHYTHM_MAP = {
    "sc_protraction": ("SC_protraction", +1.0),
    "sc_elevation": ("SC_elevation", -1.0),
    "sc_posterior_rotation": ("SC_rotation", +1.0),
}
ST_COLUMNS = ("ST_protraction", "ST_medRotation", "ST_tilt")  # same convention as scapula_isb_angles
_NEWTON_TOL = 1e-13
FREE = ("ac_protraction", "ac_upward_rotation")  # solved from g(q) = 0 in every frame
FITTED = "ac_posterior_tilt"  # the scapular rotation the constraints leave free: fitted to the rhythm


def sc_in_isb_frame(kin: Kinematics, splines: dict[str, CubicSpline]) -> dict[str, CubicSpline]:
    """Put Ludewig's SC changes on the ISB clavicle frame (Y-X'-Z'' from the model's reference
    ISB SC angles), not on the model's thorax-parallel SC axes, and express the result in the
    model's SC coordinates, splined over HT elevation. (Applied to the model's axes directly, a
    clavicle elevation change about thorax -X also turns the clavicle about its own oblique axis,
    and the acromion ends up lower than Ludewig's clavicle at high elevation.)"""
    from exubio.model.angles import anatomical_frames, euler_angles, rotation_from_euler

    model = kin.model
    A = anatomical_frames(model)["clavicle"]  # ISB clavicle frame at q = 0 (segment = thorax axes)
    ref = euler_angles(A, "YXZ")
    nodes = np.radians(np.arange(0.0, 160.1, 2.5))
    delta = np.stack([splines["sc_protraction"](nodes), -splines["sc_elevation"](nodes),
                      splines["sc_posterior_rotation"](nodes)], axis=1)  # Ludewig's ΔY, ΔX, ΔZ
    R_seg = rotation_from_euler(ref + delta, "YXZ") @ A.T
    R_all = np.tile(np.eye(3), (nodes.size, len(model.segments), 1, 1))
    ci = model.segment_index("clavicle")
    R_all[:, ci] = R_seg
    q = kin.coordinates_from_rotations(R_all)
    out = dict(splines)
    for c in model.segment("clavicle").joint.coordinates:
        out[c] = CubicSpline(nodes, q[:, model.coordinate_names.index(c)], bc_type="natural")
    return out


def rhythm_splines(plane: str) -> dict[str, CubicSpline]:
    """Natural cubic splines (HT elevation, rad -> change, rad) of every rhythm column: the change
    from the lowest tabulated elevation (30 deg), linear below it (30->45 deg slope), shifted to
    be zero at 0 deg. Keys: the model SC coordinate names and the ST column names."""
    table = LUDEWIG_2009[plane]
    ht = np.array(LUDEWIG_HT_DEG)
    nodes = np.concatenate([[0.0, 15.0], ht])
    out = {}
    cols = [(name, col, sign) for name, (col, sign) in RHYTHM_MAP.items()] + [(c, c, 1.0) for c in ST_COLUMNS]
    for key, col, sign in cols:
        v = sign * (np.array(table[col]) - table[col][0])
        slope = (v[1] - v[0]) / (ht[1] - ht[0])
        vals = np.concatenate([slope * (nodes[:2] - ht[0]), v]) + slope * ht[0]  # zero at 0 deg
        out[key] = CubicSpline(np.radians(nodes), np.radians(vals), bc_type="natural")
    return out


# --------------------------------------------------------------------------------------------
# Constraint solution
# --------------------------------------------------------------------------------------------
def solve_free(kin: Kinematics, q: np.ndarray, free: np.ndarray, *, max_iter: int = 40) -> np.ndarray:
    """Newton on g(q) = 0 for the two free coordinates, all frames at once (exubio.methods.lsq.newton; q
    modified in place; steps limited to 0.1 rad). Raises ModelError naming the frames that do not
    converge and why the iteration stopped."""
    from exubio.methods.lsq import newton

    def update(qq: np.ndarray, g: np.ndarray, _) -> np.ndarray:
        G = kin.G(qq)[..., free]
        dq = np.linalg.solve(G, -g[..., None])[..., 0]
        step = np.max(np.abs(dq), axis=-1, keepdims=True)
        qq[..., free] += dq * np.minimum(1.0, 0.1 / np.maximum(step, 1e-300))
        return qq

    solved = newton(q, lambda qq: (kin.g(qq), None), update, tol=_NEWTON_TOL, max_iterations=max_iter)
    if solved.converged:
        return q
    g = np.abs(kin.g(q)).reshape(-1, 2).max(axis=-1)
    bad = np.flatnonzero(~(g <= _NEWTON_TOL))
    raise ModelError(
        f"{kin.model.source or kin.model.name}: the scapula cannot be put on the thorax ellipsoid in "
        f"{bad.size} frame(s) (first {bad[0]}, |g| = {g[bad[0]]:.2e}) with {list(FREE)} free "
        f"(Newton stopped: {solved.reason.label.replace('_', ' ')})"
    )


def scapula_isb_angles(kin: Kinematics, q: np.ndarray, /) -> np.ndarray:
    """Scapulothoracic angles (..., 3) in rad of the ISB scapula frame built from the model's AA,
    TS and AI (Wu et al. 2005: Z from TS to AA, X normal to the AI-AA-TS plane, anterior), in
    the ISB sequence Y-X'-Z'' relative to the thorax: [internal rotation (+), X' (negative =
    upward rotation), posterior tilt (+)], Ludewig's ST convention."""
    pts = kin.point_set([("scapula", "AA"), ("scapula", "TS"), ("scapula", "AI")])
    p = kin.points(q, pts)
    aa, ts, ai = p[..., 0, :], p[..., 1, :], p[..., 2, :]
    z = aa - ts
    z /= np.linalg.norm(z, axis=-1, keepdims=True)
    x = np.cross(ts - ai, aa - ai)  # anterior for a right scapula
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    # R = [x y z] = Ry(a) Rx(b) Rz(c): R[:,2] = (sa cb, -sb, ca cb), R[1,:] = (cb sc, cb cc, -sb)
    a = np.arctan2(z[..., 0], z[..., 2])
    b = np.arcsin(np.clip(-z[..., 1], -1.0, 1.0))
    c = np.arctan2(x[..., 1], y[..., 1])
    return np.stack([a, b, c], axis=-1)


def girdle_calibration(kin: Kinematics, splines: dict[str, CubicSpline], free: np.ndarray):
    """On a 5-deg grid of HT elevation (0-120 deg) with the SC coordinates on the rhythm, choose
    ac_posterior_tilt (the one scapular rotation left free by the two ellipsoid constraints, which
    fix ac_protraction and ac_upward_rotation) so that the ISB scapulothoracic angle changes
    from 0 deg (scapula_isb_angles) are as close as possible, in least squares over the three
    angles, to Ludewig's ST changes. Newton on the derivative of that cost (central differences),
    all grid points at once. Returns splines over HT elevation of ac_posterior_tilt and of the two
    solved coordinates (warm start), and the grid table in degrees: HT, the six SC/AC
    coordinates, the model's ST changes, Ludewig's ST changes."""
    names = kin.model.coordinate_names
    grid = np.radians(np.arange(0.0, 120.0 + 1e-9, 5.0))
    q = np.zeros((grid.size, len(names)))
    solve_free(kin, q, free)
    ref = scapula_isb_angles(kin, q[0])
    sc = [names.index(c) for c in RHYTHM_MAP]
    final = np.stack([splines[c](grid) for c in RHYTHM_MAP], axis=-1)
    for lam in np.linspace(0.1, 1.0, 10):  # continuation from the reference posture
        q[:, sc] = lam * final
        solve_free(kin, q, free)
    target = np.stack([splines[c](grid) for c in ST_COLUMNS], axis=-1)
    i_fit = names.index(FITTED)
    h = 1e-4

    def cost(u: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        qq = q0.copy()
        qq[:, i_fit] = u
        solve_free(kin, qq, free)
        d = scapula_isb_angles(kin, qq) - ref - target
        return np.sum(d * d, axis=-1), qq

    for _ in range(40):
        u = q[:, i_fit].copy()
        c0, q = cost(u, q)
        cp, _ = cost(u + h, q)
        cm, _ = cost(u - h, q)
        d1, d2 = (cp - cm) / (2 * h), (cp - 2 * c0 + cm) / h**2
        step = np.where(d2 > 0, -d1 / np.where(d2 > 0, d2, 1.0), -np.sign(d1) * 0.05)
        step = np.clip(step, -0.05, 0.05)
        q[:, i_fit] = u + step
        if np.max(np.abs(step)) < 1e-10:
            break
    else:
        raise ModelError(f"{kin.model.source or kin.model.name}: the scapulothoracic rhythm could not be fitted "
                         f"(last step {np.max(np.abs(step)):.1e} rad)")
    solve_free(kin, q, free)
    st = np.degrees(scapula_isb_angles(kin, q) - ref)
    table = np.column_stack([np.degrees(grid), np.degrees(q[:, :6]), st, np.degrees(target)])
    return (CubicSpline(grid, q[:, i_fit], bc_type="natural"),
            CubicSpline(grid, q[:, free[0]]), CubicSpline(grid, q[:, free[1]]), table)


def rhythm_poses(model: Model, plane: str, ht_deg: np.ndarray, /) -> np.ndarray:
    """Postures (n, m) of the shoulder girdle on Ludewig's rhythm in ``plane`` ('frontal',
    'scapular', 'sagittal') at HT elevations ``ht_deg``, WITHOUT the ellipsoid constraint: the
    clavicle turned by Ludewig's SC changes (as in the simulation) and the scapula by all three of
    Ludewig's ST changes, applied to the model's reference ISB scapula frame (scapula_isb_angles).
    Arm coordinates zero. The contact points of these postures are what a thorax ellipsoid must
    carry (``exubio.calibration.ellipsoid.fit_ellipsoid_to_points``)."""
    from exubio.model.angles import rotation_from_euler

    kin = Kinematics(model)
    splines = sc_in_isb_frame(kin, rhythm_splines(plane))
    th = np.radians(np.asarray(ht_deg, dtype=float))
    names = model.coordinate_names
    q = np.zeros((th.size, len(names)))
    for c in RHYTHM_MAP:
        q[:, names.index(c)] = splines[c](th)
    ref = scapula_isb_angles(kin, np.zeros(len(names)))
    A0 = rotation_from_euler(ref, "YXZ")  # ISB scapula frame at q = 0 (scapula axes = thorax axes)
    delta = np.stack([splines[c](th) for c in ST_COLUMNS], axis=-1)
    R_scap = rotation_from_euler(ref + delta, "YXZ") @ A0.T
    fr = kin.frames(q)
    R_all = fr.R.copy()
    R_all[:, model.segment_index("scapula")] = R_scap
    ac = [names.index(c) for c in model.segment("scapula").joint.coordinates]
    q[:, ac] = kin.coordinates_from_rotations(R_all)[:, ac]
    return q


RHYTHM_TABLE_COLUMNS = (
    "ht_elevation", "sc_protraction", "sc_elevation", "sc_posterior_rotation", "ac_protraction",
    "ac_upward_rotation", "ac_posterior_tilt", "model_st_internal_rotation", "model_st_x", "model_st_tilt",
    "ludewig_st_internal_rotation", "ludewig_st_x", "ludewig_st_tilt",
)  # fmt: skip
