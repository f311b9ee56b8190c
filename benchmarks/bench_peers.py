"""exubio's PF and LS beside the peers that are installed, on one simulated trial, in one run.

The trial is bench_reconstruction.py's (25 s of abduction at 200 Hz, 5000 frames, 1.5 mm marker
noise, the shipped model and protocol, prepared by ``prepare_targets``). The peers get the same
chain: the model exported by exubio.export (``biomod_text``, ``osim_text`` with the thorax welded to the ground, as exubio holds it) with the protocol's
markers as the model's markers (the other model points left out), and the same prepared marker
positions (thorax frame, low-pass filtered, m). Timed per method: the solve over every frame,
median of ``--runs`` runs, CPU time of this process pinned to one core (BLAS threads 1); model
loading and data conversion are not timed.

- exubio PF and LS: ``exubio.run.pipeline.reconstruct`` (as bench_reconstruction.py).
- biorbd's Kalman filter (``biorbd.KalmanReconsMarkers``, C++; frame by frame).
- biorbd's Gauss-Newton inverse kinematics (``biorbd.InverseKinematics``: scipy's Levenberg-Marquardt
  per frame on biorbd's markers and Jacobians, ``solve("only_lm")``).
- OpenSim's inverse kinematics (``opensim.InverseKinematicsSolver``: ``assemble`` at the first
  frame, ``track`` at every next one, accuracy 1e-5).

The peers solve the open chain (a .bioMod or this .osim does not hold exubio's scapulothoracic
ellipsoid constraint): they do less per frame than exubio's PF and LS. Each line gives ms/frame, the
ratios to exubio's PF and LS, and the RMSE (deg) of the joint coordinates against the simulation's
truth (the coordinates of every tool are exubio's, in exubio's order; the clavicle's held axial
rotation left out), so a fast peer that is wrong shows it.

    python benchmarks/bench_peers.py                 # 3 runs each
    python benchmarks/bench_peers.py --runs 1 --duration 5
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: before numpy is imported

import argparse  # noqa: E402
import contextlib  # noqa: E402
import dataclasses  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import locale  # noqa: E402
import re  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PREFIX = "trk_"  # the protocol markers' names in the exported models


def peer_model(model, protocol):
    """The model with the protocol's markers added as model points (PREFIX + name)."""
    segments = tuple(dataclasses.replace(s, points={**s.points, **{PREFIX + m.name: np.asarray(m.local_position_m, float)
                                                                   for m in protocol.markers if m.segment == s.name}})
                     for s in model.segments)
    return dataclasses.replace(model, segments=segments)


def write_peer_files(model, protocol, folder: Path) -> tuple[Path, Path]:
    """A .bioMod and an .osim of the model whose only markers are the protocol's."""
    from exubio.export.biomod import biomod_text
    from exubio.export.osim import osim_text

    pm = peer_model(model, protocol)
    bio = re.sub(r"marker (?!%s)\S+\n.*?endmarker\n" % PREFIX, "", biomod_text(pm), flags=re.S)
    osim = re.sub(r'\t*<Marker name="(?!%s)[^"]*">.*?</Marker>\n' % PREFIX, "", osim_text(pm, coordinates="model", thorax="weld"),
                  flags=re.S)
    (folder / "peer.bioMod").write_text(bio)
    (folder / "peer.osim").write_text(osim)
    return folder / "peer.bioMod", folder / "peer.osim"


def timed(fn, runs: int):
    """(last result, CPU s of every run)."""
    out, cpu = None, []
    for _ in range(runs):
        c0 = time.process_time()
        out = fn()
        cpu.append(time.process_time() - c0)
    return out, cpu


def biorbd_kalman(path: Path, markers: np.ndarray, names: list[str], rate_hz: float):
    """q (n, m) from biorbd's Kalman filter; markers (n, k, 3) in protocol order, NaN = missing."""
    import biorbd

    bio = biorbd.Model(str(path))
    order = [names.index(n.to_string()[len(PREFIX):]) for n in bio.markerNames()]
    data = markers[:, order]

    def run():
        kalman = biorbd.KalmanReconsMarkers(bio, biorbd.KalmanParam(rate_hz))
        q, qd, qdd = biorbd.GeneralizedCoordinates(bio), biorbd.GeneralizedVelocity(bio), biorbd.GeneralizedAcceleration(bio)
        out = np.empty((data.shape[0], bio.nbQ()))
        for i, frame in enumerate(data):
            kalman.reconstructFrame(bio, [biorbd.NodeSegment(p) for p in frame], q, qd, qdd)
            out[i] = q.to_array()
        return out
    return run


def biorbd_ik(path: Path, markers: np.ndarray, names: list[str]):
    import biorbd

    bio = biorbd.Model(str(path))
    order = [names.index(n.to_string()[len(PREFIX):]) for n in bio.markerNames()]
    data = np.ascontiguousarray(markers[:, order].transpose(2, 1, 0))  # (3, k, n) as biorbd wants

    def run():
        with contextlib.redirect_stdout(io.StringIO()):  # it prints every 100th frame
            return biorbd.InverseKinematics(bio, data).solve("only_lm").T
    return run


def opensim_ik(path: Path, markers: np.ndarray, names: list[str], rate_hz: float):
    import opensim

    opensim.Logger.setLevelString("error")
    osim = opensim.Model(str(path))
    state = osim.initSystem()
    labels = [PREFIX + n for n in names]
    table = opensim.TimeSeriesTableVec3()
    table.setColumnLabels(labels)
    for i, frame in enumerate(markers):
        row = opensim.RowVectorVec3(len(labels))
        for j, p in enumerate(frame):
            row[j] = opensim.Vec3(*[float(x) for x in p])
        table.appendRow(i / rate_hz, row)
    coords = osim.getCoordinateSet()
    n_q = coords.getSize()

    def run():
        mref = opensim.MarkersReference(table, opensim.SetMarkerWeights())
        solver = opensim.InverseKinematicsSolver(osim, mref, opensim.SimTKArrayCoordinateReference(), float("inf"))
        solver.setAccuracy(1e-5)
        out = np.empty((markers.shape[0], n_q))
        state.setTime(0.0)
        solver.assemble(state)
        for i in range(markers.shape[0]):
            if i:
                state.setTime(i / rate_hz)
                solver.track(state)
            out[i] = [coords.get(c).getValue(state) for c in range(n_q)]
        return out
    return run


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=25.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--noise-mm", type=float, default=1.5)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    try:
        cpu_id = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu_id})
    except (AttributeError, OSError):
        cpu_id = None
    from exubio.prep.targets import prepare_targets
    from exubio.run.inputs import load_model_and_protocol
    from exubio.run.pipeline import reconstruct
    from exubio.synth.simulate import Motion, simulate_trial

    model, protocol = load_model_and_protocol()
    trial = simulate_trial(model, Motion.parse("abduction"), duration_s=args.duration, rate_hz=args.rate,
                           noise_mm=args.noise_mm, sta_mm=0.0, seed=1)
    targets = prepare_targets(trial.trajectories, protocol)
    n = targets.n_frames
    truth = trial.q_true
    held = np.array([c in protocol.held_coordinates for c in model.coordinate_names])
    names = list(targets.marker_names)
    methods = {"exubio PF": lambda: reconstruct(model, protocol, targets, method="pf").q_rad,
               "exubio LS": lambda: reconstruct(model, protocol, targets, method="ls").q_rad}
    before = locale.setlocale(locale.LC_ALL)
    with tempfile.TemporaryDirectory(prefix="exubio-peers-") as tmp:
        bio_path, osim_path = write_peer_files(model, protocol, Path(tmp))
        skipped = []
        for label, make in (("biorbd Kalman filter", lambda: biorbd_kalman(bio_path, targets.positions_m, names, args.rate)),
                            ("biorbd Gauss-Newton IK", lambda: biorbd_ik(bio_path, targets.positions_m, names)),
                            ("OpenSim IK", lambda: opensim_ik(osim_path, targets.positions_m, names, args.rate))):
            try:
                methods[label] = make()
            except ImportError as exc:
                skipped.append(f"{label}: not installed ({exc})")
        rows = []
        for label, fn in methods.items():
            q, cpu = timed(fn, args.runs)
            locale.setlocale(locale.LC_ALL, before)  # biorbd sets the C locale of the process
            ms = 1e3 * statistics.median(cpu) / n
            err = np.degrees(np.sqrt(np.nanmean((q - truth) ** 2, axis=0)))[~held]
            rows.append({"method": label, "ms_per_frame": ms, "cpu_ms_per_frame_runs": [1e3 * c / n for c in cpu],
                         "max_rmse_deg": float(np.nanmax(err)), "median_rmse_deg": float(np.nanmedian(err))})
    pf = next(r["ms_per_frame"] for r in rows if r["method"] == "exubio PF")
    ls = next(r["ms_per_frame"] for r in rows if r["method"] == "exubio LS")
    load = os.getloadavg()
    print(f"{args.duration:g} s abduction at {args.rate:g} Hz ({n} frames), noise {args.noise_mm:g} mm, {len(names)} markers, "
          f"13-coordinate chain; median of {args.runs} run(s), CPU time on core {cpu_id}; load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"{'method':<26} {'ms/frame':>9} {'/ PF':>7} {'/ LS':>7} {'RMSE deg (max / median)':>24}")
    for r in rows:
        r["ratio_to_pf"], r["ratio_to_ls"] = r["ms_per_frame"] / pf, r["ms_per_frame"] / ls
        print(f"{r['method']:<26} {r['ms_per_frame']:9.3f} {r['ratio_to_pf']:7.2f} {r['ratio_to_ls']:7.2f} "
              f"{r['max_rmse_deg']:13.2f} / {r['median_rmse_deg']:.2f}")
    for s in skipped:
        print(s)
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "skipped": skipped, "load_average": load}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
