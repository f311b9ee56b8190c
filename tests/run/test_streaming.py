"""Chunked (streaming) reconstruction: PF keeps integrating across chunk boundaries, LS carries its
warm start, and the result is the one-pass result; the pipeline writes the same files whatever
the chunk size and leaves no part file behind, also when a run fails."""
from __future__ import annotations

import dataclasses
import filecmp
import os

import numpy as np
import pytest

from exubio.errors import ReconstructionError
from exubio.io.results import read_npz, write_npz
from exubio.io.streamed import ArrayFile
from exubio.methods.common import Collector, chunk_bounds
from exubio.methods.ls import reconstruct_ls, stream_ls
from exubio.methods.pf import PFOptions, reconstruct_pf, stream_pf
from exubio.run.pipeline import RunSettings, load_inputs, reconstruct_file
from exubio.io.resources import shipped_file

pytestmark = pytest.mark.exudyn

EXAMPLE = shipped_file("exubio.data", "example_abduction.c3d", "exubio/data")


@pytest.fixture(scope="module")
def inputs():
    return load_inputs(EXAMPLE)


def _joined(stream, inputs, size, **kw):
    chunks = Collector()
    timings, info = stream(inputs.binding, inputs.targets, chunks, chunk_frames=size, **kw)
    return chunks, chunks.reconstruction(inputs.targets, timings_s=timings, info=info)


def test_chunk_bounds_cover_the_frames_in_order():
    assert chunk_bounds(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert chunk_bounds(10, 4, first=1) == [(0, 5), (5, 9), (9, 10)]
    assert chunk_bounds(3, 10, first=1) == [(0, 3)]


@pytest.mark.parametrize("size", [37, 250])
def test_pf_in_chunks_equals_one_pass(inputs, size):
    one = reconstruct_pf(inputs.model, inputs.protocol, inputs.targets)
    chunks, joined = _joined(stream_pf, inputs, size)
    assert len(chunks.chunks) == -(-inputs.targets.n_frames // size)
    assert [c.n_frames for c in chunks.chunks[:-1]] == [size] * (len(chunks.chunks) - 1)
    assert np.abs(joined.q_rad - one.q_rad).max() <= 1e-12
    assert np.abs(joined.qd_rad_s - one.qd_rad_s).max() <= 1e-9
    assert np.abs(joined.qdd_rad_s2 - one.qdd_rad_s2).max() <= 1e-9
    assert np.abs(joined.model_points_m - one.model_points_m).max() <= 1e-12
    assert np.abs(joined.constraint).max() < 1e-10  # every chunk projected on the ellipsoid


@pytest.mark.parametrize("size", [20, 333])
def test_ls_in_chunks_equals_one_pass(inputs, size):
    one = reconstruct_ls(inputs.model, inputs.protocol, inputs.targets)
    chunks, joined = _joined(stream_ls, inputs, size)
    assert len(chunks.chunks) > 1
    np.testing.assert_array_equal(joined.q_rad, one.q_rad)
    np.testing.assert_array_equal(joined.status, one.status)
    assert np.abs(joined.qdd_rad_s2 - one.qdd_rad_s2).max() <= 1e-9


def test_pf_divergence_stops_the_integration_at_the_chunk_that_shows_it(inputs):
    seen = []
    with pytest.raises(ReconstructionError, match="diverged"):
        stream_pf(inputs.binding, inputs.targets, seen.append, chunk_frames=100,
                  options=PFOptions(divergence_deflection_m=1e-4))
    assert seen == []  # the first chunk already fails: nothing of it was handed on


def test_array_file_round_trip_and_npz_layout(tmp_path):
    rng = np.random.default_rng(1)
    data = rng.normal(size=(1003, 4, 3))
    f = ArrayFile(tmp_path / ".x.tmp.part", data.shape)
    for a in range(0, 1003, 100):
        f.append(data[a:a + 100])
    assert f.complete
    np.testing.assert_array_equal(np.concatenate(list(f.blocks())), data)
    f.remove()
    assert not (tmp_path / ".x.tmp.part").exists()
    with pytest.raises(ValueError):
        ArrayFile(tmp_path / ".y.tmp.part", (2, 4, 3)).append(np.zeros((3, 4, 3)))


def test_a_restarted_sink_holds_only_the_second_run(inputs, tmp_path):
    """PF's fallback runs the trial again into the same sink (restart): what the first run handed
    on is gone, from memory and from the model points' part file, and the result is the second's."""
    from exubio.io.streamed import StreamedReconstruction

    recon = reconstruct_ls(inputs.model, inputs.protocol, inputs.targets)
    n = recon.n_frames
    other = dataclasses.replace(recon, q_rad=recon.q_rad + 1.0, model_points_m=recon.model_points_m + 1.0)
    sink = StreamedReconstruction(tmp_path, "t_ls", inputs.targets, recon.coordinate_names)
    sink(dataclasses.replace(other, **{k: getattr(other, k)[: n // 2] for k in _FRAME_FIELDS}))  # a first run, half way
    sink.restart()
    for a, b in ((0, n // 3), (n // 3, n)):
        sink(dataclasses.replace(recon, **{k: getattr(recon, k)[a:b] for k in _FRAME_FIELDS}))
    got = sink.reconstruction(timings_s={}, info={})
    np.testing.assert_array_equal(got.q_rad, recon.q_rad)
    np.testing.assert_array_equal(np.concatenate(list(sink.model_points.blocks())), recon.model_points_m)
    sink.discard()
    assert not [p for p in tmp_path.iterdir()]
    chunks = Collector()
    chunks(other)
    chunks.restart()
    chunks(recon)
    np.testing.assert_array_equal(chunks.reconstruction(inputs.targets, timings_s={}, info={}).q_rad, recon.q_rad)


_FRAME_FIELDS = ("time_s", "q_rad", "qd_rad_s", "qdd_rad_s2", "model_points_m", "measured_m", "residuals_m",
                 "constraint", "constraint_velocity", "status")


def test_streamed_npz_equals_the_in_memory_one(inputs, tmp_path):
    recon = reconstruct_ls(inputs.model, inputs.protocol, inputs.targets)
    write_npz(tmp_path / "a.npz", recon, metadata={"x": 1})
    f = ArrayFile(tmp_path / ".mp.tmp.part", recon.model_points_m.shape)
    f.append(recon.model_points_m)
    import dataclasses

    write_npz(tmp_path / "b.npz", dataclasses.replace(recon, model_points_m=None), metadata={"x": 1},
              streamed={"model_points_m": f})
    a, b = read_npz(tmp_path / "a.npz"), read_npz(tmp_path / "b.npz")
    for name in ("q_rad", "model_points_m", "measured_m", "residuals_m", "status"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert filecmp.cmp(tmp_path / "a.npz", tmp_path / "b.npz", shallow=False)  # the np.savez layout, byte for byte


def test_pipeline_files_do_not_depend_on_the_chunk_size(tmp_path):
    whole = reconstruct_file(EXAMPLE, tmp_path / "whole", methods=["pf", "ls"], settings=RunSettings(chunk_frames=100000))
    small = reconstruct_file(EXAMPLE, tmp_path / "small", methods=["pf", "ls"], settings=RunSettings(chunk_frames=60))
    assert all(o.reconstruction.model_points_m is None for o in whole + small)  # left on disk, not in memory
    for (pa, sa), (pb, sb) in zip(((o.paths, o.summary) for o in whole), ((o.paths, o.summary) for o in small)):
        for kind in ("csv", "mot"):
            assert filecmp.cmp(pa[kind], pb[kind], shallow=False), kind
        a, b = read_npz(pa["npz"]), read_npz(pb["npz"])
        np.testing.assert_array_equal(a.q_rad, b.q_rad)
        np.testing.assert_array_equal(a.model_points_m, b.model_points_m)
        assert sa["quality"] == sb["quality"]
        assert sa["residual_mm"]["max"] == pytest.approx(sb["residual_mm"]["max"], abs=1e-12)
    for folder in ("whole", "small"):
        assert not [p for p in (tmp_path / folder).iterdir() if p.name.startswith(".")]  # no part file left


def test_a_failing_run_leaves_no_part_file(tmp_path):
    with pytest.raises(ReconstructionError):
        reconstruct_file(EXAMPLE, tmp_path, methods=["pf"], settings=RunSettings(
            chunk_frames=50, method_options={"pf": {"divergence_deflection_m": 1e-4}}))
    assert list(tmp_path.iterdir()) == []


def test_a_killed_writers_leftovers_are_removed_by_the_next_run(tmp_path):
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    pid = int(dead.stdout)
    out = tmp_path / "out"
    out.mkdir()
    killed = [out / f".example_abduction.pf.{pid}.0123abcd.tmp.model_points",
              out / f".example_abduction.pf.csv.{pid}.89abcdef.tmp.csv"]
    running = out / f".example_abduction.pf.csv.{os.getpid()}.0123abcd.tmp.csv"  # a writer still at work
    other = out / f".other_trial.pf.csv.{pid}.0123abcd.tmp.csv"  # not this run's results
    for p in killed + [running, other]:
        p.write_bytes(b"partial")
    reconstruct_file(EXAMPLE, out, methods=["pf"])
    assert not any(p.exists() for p in killed)
    assert running.exists() and other.exists()
    assert (out / "example_abduction.pf.npz").is_file()


def test_a_result_can_be_read_without_its_points(tmp_path):
    """A report of a long trial reads the angles and residuals, not the per-marker 3-D arrays."""
    [outcome] = reconstruct_file(EXAMPLE, tmp_path, methods=["ls"])
    paths = outcome.paths
    full, light = read_npz(paths["npz"]), read_npz(paths["npz"], points=False)
    assert light.model_points_m is None and light.measured_m is None
    np.testing.assert_array_equal(light.q_rad, full.q_rad)
    np.testing.assert_array_equal(light.residuals_m, full.residuals_m)


def test_a_file_run_that_finishes_on_pfs_fallback_writes_the_second_run_and_says_so(tmp_path):
    """Springs a tenth of the sensitivity grid's weakest corner (c = 1 N/m, d = 0.01 Ns/m) on the real
    abduction, run as `exubio reconstruct` runs a trial (streamed in chunks to the part file): the
    limb's inertia makes them lag 250 mm behind their markers and PF's first run stops, the fallback
    (inertia x 0.01) runs it again into the same sink started again, and the files hold the second run
    alone (the same as the in-memory run), the summary and the verdict say so, no part file is left.
    (The grid's corner itself, c = 10 N/m, stopped the first run only while gh_abduction and
    gh_flexion had ranges: their limits near the sequence's lock spun the humerus at 1500 rad/s.)"""
    from exubio.run.inputs import load_session
    from exubio.run.pipeline import reconstruct
    from exubio.validation.sensitivity import with_springs
    from exubio.validation.trials import why_no_real_trial
    from exubio.validation.paths import shared_data_dir

    if why_no_real_trial("abduction"):
        pytest.skip(why_no_real_trial("abduction"))
    session = load_session(protocol_path=shipped_file("exubio.protocols", "thoracoscapular_9.yaml", "protocols"))
    corner = dataclasses.replace(session, protocol=with_springs(session.protocol, 1.0, 0.01))
    trial = shared_data_dir() / "trc" / "tsm_rmr_ABD01.trc"
    (outcome,) = reconstruct_file(trial, tmp_path, methods=["pf"], session=corner, settings=RunSettings(chunk_frames=200))
    paths, summary = outcome.paths, outcome.summary
    codes = {r["code"]: r["level"] for r in summary["quality"]["reasons"]}
    assert codes.get("solver_fallback") == "note"
    written = read_npz(paths["npz"])
    inputs = load_inputs(trial, corner)
    memory = reconstruct(inputs.model, inputs.protocol, inputs.targets, method="pf")
    assert memory.info["fallback"]["options"] == {"inertia_scale": 0.01, "modified_newton": False}
    np.testing.assert_allclose(written.q_rad, memory.q_rad, atol=1e-12)
    np.testing.assert_allclose(written.model_points_m, memory.model_points_m, atol=1e-12)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
