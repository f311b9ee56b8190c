"""What the bone-pin studies (studies/bone_u_*.py) share: their command line (the shared data folder and a
folder of held-out trials) and the quiet set-up that reads the generic model. Imported by those scripts
(run as ``python studies/<name>.py``, which puts this folder on the path)."""
from __future__ import annotations

import argparse
import logging
import sys
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "truth" / "sta_opendata"
RATE = 300.0  # the S2M pin trials' rate (the data-sharing format stores none)


def bone_parser(doc: str) -> argparse.ArgumentParser:
    """--data (the shared pin trials) and --held (a folder of S2M trials never fitted); add the study's own."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--held", type=Path, help="a folder of S2M trials never fitted")
    return ap


def quiet_generic_model(data: Path) -> dict | None:
    """The generic model (its YAML as a mapping), with logging's warnings and Python's warnings off for the
    study's many runs; None (said on stderr) where ``data`` is no folder."""
    if not data.is_dir():
        print(f"no data at {data}", file=sys.stderr)
        return None
    from exubio.errors import ModelError
    from exubio.io.yaml import read_yaml
    from exubio.model.load import DEFAULT_MODEL

    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    return read_yaml(DEFAULT_MODEL, error=ModelError)
