"""One trial flows through the run once: with ``--static-frames`` (calibrated on its own frames) and
``--method both``, the model file, the protocol file and the trial are each parsed or prepared
exactly once, counted by wrapping the parsers where they are called from."""
from __future__ import annotations

import collections
import sys
from pathlib import Path

import pytest

from exubio.cli import main
from exubio.io.resources import shipped_file

pytestmark = pytest.mark.exudyn

EXAMPLE = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")


def _wrap_everywhere(monkeypatch, original, counter, key):
    """Replace ``original`` in every loaded exubio module that holds it (a name imported with
    ``from ... import``), counting each call under ``key(*args)``."""
    def counting(*args, **kwargs):
        counter[key(*args, **kwargs)] += 1
        return original(*args, **kwargs)

    for mod in list(sys.modules.values()):
        if getattr(mod, "__name__", "").startswith("exubio"):
            for name, value in list(vars(mod).items()):
                if value is original:
                    monkeypatch.setattr(mod, name, counting)


@pytest.fixture
def counts(monkeypatch):
    import exubio.io.trial as trial_io
    import exubio.io.yaml as yaml_io
    import exubio.prep.targets as targets
    # every module of the run imported first, so that their bound names are wrapped too
    import exubio.run.job  # noqa: F401
    import exubio.run.session  # noqa: F401
    import exubio.trust.assess  # noqa: F401

    parsed: collections.Counter = collections.Counter()
    read: collections.Counter = collections.Counter()
    prepared: collections.Counter = collections.Counter()
    parse = yaml_io._parse
    monkeypatch.setattr(yaml_io, "_parse", lambda text, path, error: (parsed.update([Path(path).name]),
                                                                      parse(text, path, error))[1])
    _wrap_everywhere(monkeypatch, trial_io.read_trial, read, lambda path, *a, **k: Path(path).name)
    _wrap_everywhere(monkeypatch, targets.prepare_targets, prepared,
                     lambda traj, protocol, *a, **k: Path(traj.source).name)
    return parsed, read, prepared


def test_static_frames_and_both_methods_do_each_thing_once(counts, tmp_path, capsys):
    parsed, read, prepared = counts
    code = main(["reconstruct", str(EXAMPLE), "--static-frames", "0:50", "--method", "both", "--no-report",
                 "--out", str(tmp_path / "out"), "--quiet"])
    assert code in (0, 1), capsys.readouterr()
    assert (tmp_path / "out" / "example_abduction.pf.csv").is_file()
    assert (tmp_path / "out" / "example_abduction.ls.csv").is_file()
    assert dict(parsed) == {"upper_extremity.yaml": 1, "upper_limb_21.yaml": 1}, dict(parsed)
    assert dict(read) == {"example_abduction.c3d": 1}, dict(read)
    assert dict(prepared) == {"example_abduction.c3d": 1}, dict(prepared)
