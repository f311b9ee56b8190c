"""Published in vivo shoulder kinematics shipped with exubio: Ludewig et al. 2009 mean curves
(``exubio/data/ludewig2009.csv``; the file's header cites the sources)."""
from __future__ import annotations

import numpy as np

from exubio.resources import shipped_file


def load_ludewig2009() -> dict[str, dict[str, np.ndarray]]:
    """Ludewig et al. 2009 mean curves from ``exubio/data/ludewig2009.csv``:
    {plane: {"ht_elevation_deg": (n,), "<column>": (n,) deg}}."""
    path = shipped_file("exubio.data", "ludewig2009.csv", "exubio/data")
    lines = [ln for ln in path.read_text().splitlines() if ln and not ln.startswith("#")]
    header = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    out: dict[str, dict[str, np.ndarray]] = {}
    for plane in dict.fromkeys(r[0] for r in rows):
        sel = np.array([[float(v) for v in r[1:]] for r in rows if r[0] == plane])
        out[plane] = {name: sel[:, i] for i, name in enumerate(header[1:])}
    return out


def ludewig2009_at(ht_deg, columns, planes=("frontal", "sagittal")) -> dict[str, dict[str, tuple[float, ...]]]:
    """{plane: {column without its axis suffix: values at ``ht_deg``}}, e.g. "SC_elevation" from
    the file's "SC_elevation_X"."""
    data = load_ludewig2009()
    out: dict[str, dict[str, tuple[float, ...]]] = {}
    for plane in planes:
        cols = data[plane]
        ht = cols["ht_elevation_deg"]
        rows = [int(np.flatnonzero(ht == h)[0]) for h in ht_deg]
        out[plane] = {}
        for col in columns:
            name = next(n for n in cols if n.rsplit("_", 1)[0] == col)
            out[plane][col] = tuple(float(cols[name][i]) for i in rows)
    return out
