"""Where the validation's real data are (``shared_data_dir``) and how its outputs name paths
(``portable_paths``: relative, so that the committed outputs carry no machine's paths)."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from exubio.io.resources import _CHECKOUT

__all__ = ["portable_paths", "shared_data_dir"]


def shared_data_dir() -> Path:
    """``$EXUBIO_SHARED_DATA``, else ``../shared/data`` beside the working directory (a checkout's
    root, as the README runs it) or beside the source checkout (editable installs)."""
    env = os.environ.get("EXUBIO_SHARED_DATA")
    if env:
        return Path(env)
    candidates = [Path.cwd().parent / "shared" / "data", _CHECKOUT.parent / "shared" / "data"]
    return next((c for c in candidates if c.is_dir()), candidates[0])


def portable_paths(obj: Any, /) -> Any:
    """``obj`` (JSON-like) with every absolute path of this machine written relative: the shared
    data folder as ``../shared/data`` (as ../shared/data/SOURCES.md and the README cite it) and the
    checkout as ``.``, inside any string (error messages included). The validation outputs are
    compared across machines and committed; they must not carry one machine's paths."""
    prefixes = []
    for path, rel in ((shared_data_dir(), "../shared/data"), (_CHECKOUT, ".")):
        for form in {str(path), str(Path(path).resolve())}:
            if form and form not in (".", "/"):
                prefixes.append((form, rel))
    prefixes.sort(key=lambda pr: -len(pr[0]))  # the longest (most specific) first

    def fix(x: Any) -> Any:
        if isinstance(x, str):
            for form, rel in prefixes:
                x = x.replace(form, rel)
            return x
        if isinstance(x, dict):
            return {fix(k): fix(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [fix(v) for v in x]
        return x

    return fix(obj)
