"""Which coordinates and ISB angles a trial's markers do not determine: there PF and LS settle
differently, so the validation greys them in Fig. 5 and leaves them out of the PF-LS agreement."""
from __future__ import annotations

import numpy as np

from exubio.model.kinematics import Kinematics
from exubio.types import Model, Protocol, Reconstruction
from exubio.validation.trials import Trial

__all__ = ["UNDETERMINED_RELATIVE_SINGULAR_VALUE", "UNDETERMINED_SHARE", "trial_undetermined",
           "undetermined_coordinates", "undetermined_isb", "unobserved_segments"]

UNDETERMINED_RELATIVE_SINGULAR_VALUE = 1e-6
UNDETERMINED_SHARE = 0.1


def undetermined_coordinates(model: Model, protocol: Protocol, q_samples: np.ndarray, /) -> dict[str, float]:
    """How much of each coordinate lies in the motions the tracked markers do not see: the
    constrained marker Jacobian J N (N: null space of the ellipsoid constraint Jacobian G) at each
    posture of q_samples (k, m); its singular directions below 1e-6 of the largest singular value
    span the unseen motions; a coordinate's share is the norm of its row in that basis (0 = fully
    determined, 1 = not seen at all), the largest over the samples. A marker set without forearm,
    hand or clavicle markers leaves the distal coordinates and the clavicle's axial rotation (a
    mix of SC and AC coordinates) undetermined; PF and LS then settle in that null space
    differently, so comparing them there says nothing about either."""
    from exubio.protocol.bind import tracked_points

    kin = Kinematics(model)
    pts = tracked_points(kin, protocol)
    share = np.zeros(model.n_coordinates)
    for q in np.atleast_2d(q_samples):
        J = kin.point_jacobian(q, pts).reshape(-1, model.n_coordinates)
        _, _, vt = np.linalg.svd(kin.G(q))
        N = vt[2:].T
        _, sv, wt = np.linalg.svd(J @ N)
        sv = np.concatenate([sv, np.zeros(N.shape[1] - sv.size)])
        null = sv < UNDETERMINED_RELATIVE_SINGULAR_VALUE * sv[0]
        if null.any():
            basis = N @ wt[null].T
            share = np.maximum(share, np.linalg.norm(basis, axis=1))
    return dict(zip(model.coordinate_names, share.tolist()))


def trial_undetermined(tr: Trial) -> list[str]:
    """The coordinates of a reconstructed trial (LS, else PF) its markers do not determine: blind
    ones (``undetermined_coordinates`` above UNDETERMINED_SHARE at 5 postures) and those its own
    verdict calls undetermined."""
    rec = tr.recon.get("ls") or tr.recon.get("pf")
    if rec is None:
        return []
    idx = np.linspace(0, rec.n_frames - 1, 5).round().astype(int)
    share = undetermined_coordinates(tr.model, tr.protocol, rec.q_rad[idx])
    blind = [n for n, v in share.items() if v > UNDETERMINED_SHARE]
    return blind + [n for n in _weakly_determined(tr, rec) if n not in blind]


def _weakly_determined(tr: Trial, rec: Reconstruction) -> list[str]:
    """Coordinates the trial's own verdict calls undetermined (exubio.trust.observability: noise gain
    above its threshold in most frames), so that Fig. 5 and the PF-LS comparison use the same
    criterion as the quality verdict of a reconstruction."""
    from exubio.protocol.bind import tracked_points
    from exubio.trust.observability import determinacy

    kin = Kinematics(tr.model)
    names = tr.model.coordinate_names
    unseen = set(unobserved_segments(tr.model, tr.protocol))
    excluded = np.array([n in tr.protocol.held_coordinates or
                         tr.model.segments[kin.coordinate_segment[i]].name in unseen for i, n in enumerate(names)])
    det = determinacy(kin, tracked_points(kin, tr.protocol), rec.q_rad, tr.targets.present, tr.protocol.weights,
                      excluded=excluded, every=max(1, rec.n_frames // 200))
    return det.trial_undetermined()


def undetermined_isb(undetermined: list[str]) -> list[str]:
    """ISB angles not determined by the markers: the clavicle's axial rotation (SC Z'', and hence
    every AC angle) when a clavicle coordinate is undetermined while the scapula is seen; the GH
    angle a GH coordinate mainly moves (internal rotation: Y'', abduction: X, flexion: Z')."""
    out = []
    if any(c.startswith("sc_") or c.startswith("ac_") for c in undetermined):
        out += ["SC_Z", "AC_Y", "AC_X", "AC_Z"]
    gh = {"gh_internal_rotation": "GH_Y", "gh_abduction": "GH_X", "gh_flexion": "GH_Z"}
    return out + [gh[c] for c in undetermined if c in gh]


def unobserved_segments(model: Model, protocol: Protocol, /) -> list[str]:
    """Segments that neither carry a tracked marker nor have a descendant that does."""
    carried = {m.segment for m in protocol.markers if m.segment != model.segments[0].name}
    seen = set()
    for name in carried:
        seg = model.segment(name)
        while seg is not None:
            seen.add(seg.name)
            seg = model.segment(seg.parent) if seg.parent else None
    return [s.name for s in model.segments if s.name not in seen]
