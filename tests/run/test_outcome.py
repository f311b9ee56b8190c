"""A method's outcome (exubio.run.outcome.MethodOutcome) is what its files hold: the summary and
metadata it carries are those of the summary.json and .npz written from it, its PF-LS agreement
the summary's, its files named by exubio.io.result_names, and the report drawn from it in memory
gets exactly what the report of the files reads (so both draw the same picture)."""
from __future__ import annotations

import json

import numpy as np
import pytest

pytestmark = pytest.mark.exudyn

pytest.importorskip("exudyn")

from exubio.io.records import to_json  # noqa: E402
from exubio.io.resources import shipped_file  # noqa: E402
from exubio.io.result_names import set_names  # noqa: E402
from exubio.report.trial_report import read_result  # noqa: E402
from exubio.run.outcome import MethodOutcome, reported  # noqa: E402
from exubio.run.pipeline import reconstruct_file  # noqa: E402

EXAMPLE = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    return reconstruct_file(EXAMPLE, tmp_path_factory.mktemp("outcome"), methods=["pf", "ls"])


def test_the_outcome_is_what_its_files_hold(outcomes):
    assert [o.method for o in outcomes] == ["pf", "ls"]
    for o in outcomes:
        assert isinstance(o, MethodOutcome) and not o.resumed and o.assessment is not None
        assert o.stem == f"example_abduction.{o.method}"
        assert {k: p.name for k, p in o.paths.items()} == set_names(o.stem)
        on_disk = json.loads(o.paths["summary"].read_text(encoding="utf-8"))
        assert json.loads(json.dumps(o.summary, default=str)) == on_disk  # no NaN in this trial's summary
        assert to_json(o.quality) == on_disk["quality"]
        assert o.quality is o.reconstruction.quality
    written = {k: v for k, v in on_disk["pf_ls_agreement_deg"].items() if isinstance(v, float)}
    assert written and outcomes[0].agreement_deg == written == outcomes[1].agreement_deg


def test_the_report_in_memory_reads_what_the_report_of_the_files_reads(outcomes):
    for o in outcomes:
        mem, disk = reported(o), read_result(o.paths["npz"])
        assert mem.npz == disk.npz and mem.metadata == disk.metadata and mem.summary == disk.summary
        for name in ("time_s", "status", "residuals_m", "constraint", "constraint_velocity"):
            np.testing.assert_array_equal(getattr(mem.reconstruction, name), getattr(disk.reconstruction, name))
        assert mem.reconstruction.gaps == disk.reconstruction.gaps
        assert mem.reconstruction.marker_names == disk.reconstruction.marker_names
        a, b = mem.angles, disk.angles
        assert a.names == b.names and a.signs == b.signs
        for name in ("time_s", "values_rad", "status", "uncertainty_rad"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name  # bit for bit
        # the CSV's precision, not the solver's: the outcome's own angles differ from it below 1e-6 deg
        assert 0 < np.nanmax(np.abs(np.degrees(a.values_rad - o.angles.values_rad))) <= 5e-7 + 1e-12
