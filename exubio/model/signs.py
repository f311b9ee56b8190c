"""The sign conventions of the anatomical angles at the output edges: ``isb`` (the raw ISB
decompositions of exubio.model.angles, Wu et al. 2005: elevation and upward rotation negative) and
``clinical`` (what clinical papers print: elevation, abduction, flexion and upward rotation
positive). The one sign table every writer and reader uses.

Inside exubio every angle is ISB (radians); an output in the clinical convention is
``sign x isb`` per angle, with ``sign`` from CLINICAL_FLIPPED (-1 there, +1 elsewhere). The rule:
in the clinical convention every column's named motion is positive (``HT_X_elevation`` positive
when the arm is raised). Six angles differ, the ones whose ISB decomposition makes the named
motion negative: the X' (second) angles of SC, AC, ST, GH (ISB and Phadke) and HT. Every other
angle's ISB sign already makes its named motion positive (protraction, posterior rotation and
tilt, internal rotation, Phadke's forward flexion, the plane of elevation towards flexion, elbow
flexion, pronation, wrist flexion and radial deviation) and is the same in both. Left arms are
mirrored onto the right-arm model before any angle is computed, so the table holds for both arms.
An uncertainty is a magnitude: the same in both conventions.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

from exubio.errors import InputError

if TYPE_CHECKING:
    import numpy as np
# numpy and the angle definitions are imported where used: the CLI's --help imports this module

__all__ = ["SIGNS", "DEFAULT", "CLINICAL_FLIPPED", "check_signs", "factors", "convert", "meaning", "header_line",
           "signs_of_comments", "signs_of_file", "mot_note", "add_signs_arguments"]

SIGNS = ("isb", "clinical")
DEFAULT = "isb"

CLINICAL_FLIPPED: dict[str, str] = {
    "SC_X_elevation": "+ elevation, - depression",
    "AC_X_upward_rotation": "+ upward rotation, - downward",
    "ST_X_upward_rotation": "+ upward rotation, - downward",
    "GH_X_elevation": "+ elevation",
    "GH_phadke_X_elevation": "+ elevation (abduction)",
    "HT_X_elevation": "+ elevation",
}
"""The angles whose clinical sign is minus their ISB sign, with their meaning in the clinical
convention (module docstring: the named motion positive)."""

_SIGNS_PREFIX = "signs: "


def check_signs(value: object, where: str) -> str:
    """``value`` as a convention name, or InputError naming ``where`` (the key or option)."""
    if isinstance(value, str) and value.strip().lower() in SIGNS:
        return value.strip().lower()
    raise InputError(f"{where}: expected one of {', '.join(SIGNS)}, got {value!r}")


def factors(names: Sequence[str], signs: str, /) -> np.ndarray:
    """(len(names),) +1 or -1: an angle in ``signs`` is factor x its ISB value (names may end in _deg)."""
    import numpy as np

    signs = check_signs(signs, "signs")
    return np.array([-1.0 if signs == "clinical" and str(n).removesuffix("_deg") in CLINICAL_FLIPPED else 1.0
                     for n in names])


def convert(names: Sequence[str], values: np.ndarray, from_signs: str, to_signs: str, /) -> np.ndarray:
    """``values`` (..., len(names)) of the angles ``names`` in ``from_signs``, in ``to_signs`` (a new
    array; the same numbers when the conventions are the same)."""
    import numpy as np

    v = np.asarray(values, dtype=float)
    if v.shape[-1:] != (len(names),):
        raise InputError(f"angle values have shape {v.shape}, expected (..., {len(names)}) for {len(names)} names")
    return v * (factors(names, from_signs) * factors(names, to_signs))


def meaning(name: str, signs: str, /) -> str:
    """The angle's meaning with its sign in the convention (exubio.model.angles.ANATOMICAL_ANGLES for ISB)."""
    from exubio.model.angles import ANATOMICAL_ANGLES

    name = str(name).removesuffix("_deg")
    if check_signs(signs, "signs") == "clinical" and name in CLINICAL_FLIPPED:
        return CLINICAL_FLIPPED[name]
    return next((m for n, _, m in ANATOMICAL_ANGLES if n == name), "")


def header_line(signs: str, /) -> str:
    """The line of the angles CSV header that names the convention (read back by signs_of_comments)."""
    if check_signs(signs, "signs") == "isb":
        return ("signs: isb (the raw ISB decompositions, Wu et al. 2005: elevation and upward rotation are negative; "
                "each column's sign below)")
    return ("signs: clinical (elevation, abduction, flexion and upward rotation positive: the ISB decomposition "
            f"with the sign of {', '.join(CLINICAL_FLIPPED)} reversed, every other angle as in ISB; each column's "
            "sign below)")


def signs_of_comments(comments: Sequence[str], /, *, where: str = "angles file") -> str:
    """The convention an angles file's comment lines (without '#') name; ``isb`` when none does
    (files written before the switch were ISB)."""
    for line in comments:
        text = line.lstrip("# ").strip()
        if text.startswith(_SIGNS_PREFIX):
            return check_signs(text[len(_SIGNS_PREFIX):].split()[0] if text[len(_SIGNS_PREFIX):].split() else "",
                               f"{where}: its '{_SIGNS_PREFIX.strip()}' header line")
    return DEFAULT


def mot_note(signs: str, /) -> str:
    """The .mot header line (key=value) that names the convention."""
    if check_signs(signs, "signs") == "isb":
        return "exubio_signs=isb (raw ISB decompositions; each angle's sign in the .csv header)"
    return f"exubio_signs=clinical (sign of {' '.join(CLINICAL_FLIPPED)} reversed from raw ISB; each angle's sign in the .csv header)"


def add_signs_arguments(parser, /, *, default: str = "the protocol's (study file's) signs key, else isb") -> None:
    """The ``--signs`` option of the commands that write angles (reconstruct, study, demo) or play
    them (export-model); ``default``: what it is when not given, for the help."""
    parser.add_argument("--signs", choices=SIGNS, default=None,
                        help="sign convention of the angles: isb (raw ISB decompositions: elevation negative) "
                             f"or clinical (elevation, abduction, flexion, upward rotation positive); default: {default} "
                             "(docs: outputs, Sign conventions)")


def signs_of_file(csv_path, /) -> str:
    """The convention of an angles CSV of exubio (its ``signs:`` header line; ``isb`` without one)."""
    from exubio.io.results import read_angles_comments

    return signs_of_comments(read_angles_comments(csv_path), where=str(csv_path))
