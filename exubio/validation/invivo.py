"""Fig. 5: the abduction and flexion trials' SC, ST, GH angles in Ludewig et al. 2009's own
definitions against humerothoracic elevation, with Ludewig's means and the corridor of comparable
studies (``exubio.literature.invivo.compare_elevation``), for PF, LS and (simulated trials) the truth."""
from __future__ import annotations

import numpy as np

from exubio.literature.invivo import compare_elevation, inferred_joints
from exubio.literature.reference import load_ludewig2009
from exubio.io.records import decode
from exubio.validation.determinacy import trial_undetermined, undetermined_isb
from exubio.validation.results import METHODS, InvivoComparison
from exubio.validation.trials import LUDEWIG_PLANE, Trial, plot_stride

__all__ = ["invivo_comparison", "ludewig_means"]


def ludewig_means() -> dict[str, dict[str, np.ndarray]]:
    """Ludewig et al. 2009's means by plane and column (exubio.literature.reference.load_ludewig2009)."""
    return {plane: dict(cols) for plane, cols in load_ludewig2009().items()}


def invivo_comparison(trials: dict[str, Trial]) -> dict[str, InvivoComparison]:
    """Every source of the abduction and flexion trials in Ludewig's definitions, in the trial's
    plane of elevation, with the curves for Fig. 5."""
    out = {}
    for name in ("abduction", "flexion"):
        tr = trials[name]
        qs = {m: (r.q_rad if r is not None else None) for m, r in ((m, tr.recon.get(m)) for m in METHODS)}
        if tr.sim is not None:
            qs["truth"] = tr.sim.q_true
        res, arr = compare_elevation(tr.model, qs, tr.targets.time_s, LUDEWIG_PLANE[name],
                                     undetermined=undetermined_isb(trial_undetermined(tr)),
                                     inferred=inferred_joints(tr.model, tr.protocol),
                                     stride=plot_stride(tr.targets.n_frames))
        out[name] = decode(InvivoComparison, res, arr)
    return out
