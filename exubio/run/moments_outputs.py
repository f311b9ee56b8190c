"""What a run writes of its joint moments beside the moment table itself, and the options that
shape them: summary.json's ``moments`` entry (peaks per joint axis, the scapulothoracic contact
force's peak and median, the files), the ``pf_inertia_scale`` entry of every PF result (the
segments' inertia PF integrated with, asked and used, and the fallback's change), the moments
header's lines on where q'' came from, and the command-line options ``--pf-inertia-scale`` (with
the protocol key ``defaults: pf_inertia_scale``)."""
from __future__ import annotations

import argparse
import math
from typing import Any, Mapping

import numpy as np

from exubio.errors import InputError

__all__ = ["DEFAULT_PF_INERTIA_SCALE", "add_moments_arguments", "check_pf_option", "moments_comments", "moments_entry",
           "pf_inertia_entry", "pf_options"]

DEFAULT_PF_INERTIA_SCALE = 0.1
"""PFOptions.inertia_scale's default (exubio.methods.pf): kept here as the CLI's and the protocol's default."""


def add_moments_arguments(parser: argparse.ArgumentParser) -> None:
    """``--pf-inertia-scale`` of ``exubio reconstruct`` (and the study)."""
    parser.add_argument("--pf-inertia-scale", type=float, metavar="X",
                        help="PF: the segments' masses and inertias the springs accelerate, x X (default: the protocol's "
                             f"defaults: pf_inertia_scale, else {DEFAULT_PF_INERTIA_SCALE:g}; 1 = the paper's physical "
                             "segments); named in summary.json, the moments files and the report (docs: moments)")


def pf_options(args: argparse.Namespace, protocol: Any, /) -> dict[str, Any]:
    """The PF option fields the command line and the protocol set: ``gravity`` and ``inertia_scale``
    (``--pf-inertia-scale``, else the protocol's ``defaults: pf_inertia_scale``, else PF's default)."""
    out: dict[str, Any] = {"gravity": bool(getattr(args, "gravity", False))}
    scale = getattr(args, "pf_inertia_scale", None)
    where = "--pf-inertia-scale"
    if scale is None and getattr(protocol, "pf_inertia_scale", None) is not None:
        scale, where = protocol.pf_inertia_scale, f"{protocol.source or protocol.name}: defaults.pf_inertia_scale"
    if scale is not None:
        if not (math.isfinite(scale) and scale > 0):
            raise InputError(f"{where}: expected a number > 0 (the share of the segments' inertia PF integrates "
                             f"with; 1 = physical), got {scale}")
        out["inertia_scale"] = float(scale)
    return out


def check_pf_option(args: argparse.Namespace, methods: list[str], /) -> None:
    """``--pf-inertia-scale`` with no PF run is refused (it would change nothing), InputError."""
    if getattr(args, "pf_inertia_scale", None) is not None and "pf" not in methods:
        raise InputError(f"--pf-inertia-scale {args.pf_inertia_scale:g}: applies to PF, and --method "
                         f"{getattr(args, 'method', '')} runs no PF; use --method pf or both, or leave the option out")


def pf_inertia_entry(info: Mapping[str, Any] | None, /) -> dict[str, Any] | None:
    """summary.json's ``pf_inertia_scale`` of a PF result's ``info`` (None for LS): ``used`` (the
    run whose q, q', q'' were written), ``asked`` (the options'), and ``fallback`` (why they differ)."""
    info = dict(info or {})
    options = dict(info.get("options") or {})
    if "inertia_scale" not in options:
        return None
    used = float(options["inertia_scale"])
    fallback = info.get("fallback")
    entry: dict[str, Any] = {"used": used, "asked": used,
                             "meaning": "PF integrated its equations of motion with the segments' masses and "
                                        "inertias x this (the joint moments always use the real inertia)"}
    if fallback:
        asked = fallback.get("asked_inertia_scale")
        entry["asked"] = float(asked) if asked is not None else None
        entry["fallback"] = (f"PF's first run stopped ({fallback.get('first_run', '')}); the results are the fallback "
                             f"run's, with inertia x {used:g}")
    return entry


def moments_comments(moments: Any, /) -> tuple[str, ...]:
    """The moments files' lines on where q'' came from (the method; PF's inertia scale and fallback),
    the thorax's motion (measured or assumed still) and the external loads."""
    info = moments.info
    line = f"q, q', q'' of the {str(info.get('method', '')).upper()} reconstruction"
    if "pf_inertia_scale" in info:
        line += (f"; pf_inertia_scale {info['pf_inertia_scale']:g}: PF integrated its equations of motion with the "
                 "segments' inertia x this (the moments use the real inertia above)")
    out = (line,) + ((info["pf_fallback"],) if "pf_fallback" in info else ())
    if "thorax" in info:
        out += (info["thorax"],)
    return out + tuple(load.describe() for load in getattr(moments, "loads", ()))


def moments_entry(moments: Any, summary: Mapping[str, Any], stem: str, /) -> dict[str, Any]:
    """summary.json's ``moments``: exubio.dynamics.moments.moments_summary's ``summary`` plus, per
    scapulothoracic contact point, its normal force's peak (the signed value of largest size, N;
    > 0: the thorax pushes the scapula out, compression), median (N) and the share of frames in
    compression (NaN frames left out), and the files."""
    out = dict(summary)
    contact: dict[str, dict[str, float]] = {}
    for j, c in enumerate(moments.columns):
        if c.endswith("_contact_normal_N"):
            v = np.asarray(moments.values[:, j], dtype=float)
            v = v[np.isfinite(v)]
            peak = float(v[np.argmax(np.abs(v))]) if v.size else None
            contact[c.removesuffix("_contact_normal_N")] = {
                "peak_N": None if peak is None else round(peak, 4),
                "median_N": round(float(np.median(v)), 4) if v.size else None,
                "compression_share": round(float(np.mean(v > 0)), 4) if v.size else None}
    out["scapulothoracic_contact"] = contact
    out["files"] = [f"{stem}.moments.csv", f"{stem}.moments.sto"]
    return out


def add_export_arguments(parser: argparse.ArgumentParser) -> None:
    """``exubio export-model``'s ``--body-mass`` and ``--hand-load-kg``: the inverse dynamics' inertia."""
    parser.add_argument("--body-mass", type=float, metavar="KG",
                        help="write the segments' inertia the joint moments use (Dumas et al. 2007 scaled by the model's "
                             "lengths and this body mass; the thorax's: exubio.export.thorax), so OpenSim's ID tool "
                             "on the .osim gives exubio's moments (docs: moments)")
    parser.add_argument("--hand-load-kg", type=float, metavar="KG", help="with --body-mass: a mass held in the hand")
    parser.add_argument("--thorax", choices=["free", "weld"],
                        help="free: a 6-DOF joint to the ground with the thorax's mass (the .mot's thorax columns move it; "
                             "the .osim's default); weld: fixed to the ground (the .bioMod's default)")


def export_model(model: Any, args: argparse.Namespace, /) -> Any:
    """The model ``exubio export-model`` writes: ``model`` (loaded at ``--body-mass``, when given),
    with ``--body-mass`` the inverse dynamics' (exubio.dynamics.inertia.dynamics_model,
    ``--hand-load-kg`` in the hand)."""
    mass, load = getattr(args, "body_mass", None), getattr(args, "hand_load_kg", None)
    if mass is None:
        if load is not None:
            raise InputError("--hand-load-kg: the inverse dynamics' inertia needs the subject's --body-mass (kg) too")
        return model
    from exubio.dynamics.inertia import dynamics_model

    return dynamics_model(model, hand_load_kg=float(load or 0.0))
