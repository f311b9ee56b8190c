"""The command-line options of the joint moments besides --body-mass and --hand-load-kg, and the
request they make (light: argparse and a dataclass, imported when the CLI parses)."""
from __future__ import annotations

import argparse
from dataclasses import dataclass

__all__ = ["LAB_UP_CHOICES", "MomentRequest", "add_moment_arguments", "moment_request"]

LAB_UP_CHOICES = ("auto", "+x", "-x", "+y", "-y", "+z", "-z")


@dataclass(frozen=True)
class MomentRequest:
    """lab_up: the lab's vertical ("auto" or "+x" ... "-z"); loads: loads CSV paths."""

    lab_up: str = "auto"
    loads: tuple[str, ...] = ()

    def key(self) -> tuple:
        return (self.lab_up, tuple(str(p) for p in self.loads))


def add_moment_arguments(parser: argparse.ArgumentParser) -> None:
    """``exubio reconstruct``'s options of the joint moments besides --body-mass/--hand-load-kg."""
    parser.add_argument("--loads", action="append", metavar="FILE.csv",
                        help="an external force and moment at a segment point, for the joint moments (with --body-mass): "
                             "columns time_s, fx_N, fy_N, fz_N, mx_Nm, my_Nm, mz_Nm, px_m, py_m, pz_m, segment, frame "
                             "(lab|thorax|segment); filtered and resampled as the markers; give it once per load")
    parser.add_argument("--lab-up", default="auto", choices=LAB_UP_CHOICES,
                        help="the lab's vertical axis, for gravity in the joint moments (default auto: the lab axis "
                             "nearest the thorax's mean vertical)")


def moment_request(args: argparse.Namespace) -> MomentRequest:
    return MomentRequest(lab_up=getattr(args, "lab_up", "auto") or "auto", loads=tuple(getattr(args, "loads", None) or ()))
