"""Live on a real trial, and the lag each causal choice costs.

1. A real trial of ../shared/data (default: martin_dynamique, 21 markers, 100 Hz, with the model
   calibrated on its session's static trial martin_statique) is replayed with ``exubio stream`` and
   reconstructed by ``exubio live`` (two processes, LSL on 127.0.0.1 only); its angles are compared
   with the offline causal PF run of the same trial (``exubio.run.live.reconstruct_causal``, the same
   settings: they must agree to 1e-9 rad) and with the offline zero-lag reconstruction
   (``exubio reconstruct``: zero-lag Butterworth + splines, 10 ms steps): RMSE and max per
   coordinate, and the lag (the time shift that best aligns the causal angles on the zero-lag ones).
2. The lag and the error each causal choice costs (no filter, causal Butterworth 12 / 8 / 6 / 4 Hz),
   in process, on the real trial (against its zero-lag reconstruction) and on the shipped example
   (a simulated trial: against its known truth).

    python studies/live_real_trial.py [--trial T.c3d --static S.c3d] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "c3d"


def lag_and_error(q_causal: np.ndarray, q_ref: np.ndarray, rate_hz: float, cols, max_shift: int = 40):
    """Per coordinate: RMSE and max |diff| (deg) as they stand, and the lag (ms): the shift s (frames,
    -5 ... max_shift, refined between frames by a parabola through the RMSE at s - 1, s, s + 1) that
    minimises the RMSE between causal[t] and reference[t - s], with the RMSE there."""
    out = {}
    for j in cols:
        a, b = q_causal[:, j], q_ref[:, j]
        ok = np.isfinite(a) & np.isfinite(b)
        d = np.degrees(a[ok] - b[ok])
        shifts = np.arange(-5, max_shift + 1)
        rms = []
        for s in shifts:
            x, y = (a[s:], b[:len(b) - s]) if s >= 0 else (a[:s], b[-s:])
            m = np.isfinite(x) & np.isfinite(y)
            rms.append(float(np.sqrt(np.mean(np.degrees(x[m] - y[m]) ** 2))))
        rms = np.array(rms)
        k = int(np.argmin(rms))
        shift = float(shifts[k])
        if 0 < k < len(rms) - 1:
            den = rms[k - 1] - 2 * rms[k] + rms[k + 1]
            if den > 0:
                shift += 0.5 * (rms[k - 1] - rms[k + 1]) / den
        out[j] = {"rmse_deg": float(np.sqrt(np.mean(d ** 2))), "max_deg": float(np.abs(d).max()),
                  "lag_ms": 1000.0 * shift / rate_hz, "rmse_after_shift_deg": float(rms[k])}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trial", default=str(DATA / "bioptim_exo_martin_dynamique.c3d"))
    ap.add_argument("--static", default=str(DATA / "bioptim_exo_martin_statique.c3d"))
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    if not Path(args.trial).is_file():
        print(f"no trial {args.trial} (../shared/data absent?)")
        return 2
    from exubio.protocol.bind import bind
    from exubio.io.results import read_npz
    from exubio.io.trial import read_trial
    from exubio.run.live.causal import CausalOptions
    from exubio.run.live.offline import reconstruct_causal
    from exubio.run.live.options import LiveOptions
    from exubio.run.live.transport import use_config
    from exubio.run.pipeline import load_inputs, reconstruct
    from exubio.run.inputs import load_model_and_protocol, load_session
    from exubio.run.session import calibrate_file

    report: dict = {}
    with tempfile.TemporaryDirectory(prefix="exubio-live-real-") as tmp:
        tmp = Path(tmp)
        model_file = tmp / "subject.yaml"
        calibrate_file(args.static, out_path=model_file)
        model, protocol = load_model_and_protocol(model_path=model_file)
        trial = read_trial(args.trial)
        names = model.coordinate_names
        solved = [j for j, e in enumerate(bind(model, protocol).not_solved) if not e]

        # 1. exubio stream | exubio live, on 127.0.0.1
        cfg = use_config("loopback")
        env = dict(os.environ, LSLAPICFG=str(cfg))
        exe = [sys.executable, "-m", "exubio.cli"]
        sname = f"real_{os.getpid()}"
        live = subprocess.Popen(exe + ["live", "--stream", sname, "--model", str(model_file), "--out", str(tmp),
                                       "--name", "real", "--no-report", "--end-after", "2", "--publish", "", "-q"],
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        stream = subprocess.run(exe + ["stream", args.trial, "--name", sname, "--units", "mm", "--wait", "30", "-q"],
                                env=env, capture_output=True, text=True, timeout=600)
        out, err = live.communicate(timeout=600)
        if live.returncode not in (0, 1):
            print(out, err)
            return 1
        got = read_npz(tmp / "real" / "real.pf.npz")
        from exubio.run.live.record import read_recorded_markers

        recorded = read_recorded_markers(tmp / "real" / "real.markers.npz")
        causal_rec = reconstruct_causal(recorded, model, protocol)  # what live received, offline
        causal_file = reconstruct_causal(trial, model, protocol)  # the trial file itself, offline
        d_rec = float(np.nanmax(np.abs(got.q_rad - causal_rec.q_rad)))
        d_file = float(np.nanmax(np.abs(got.q_rad - causal_file.q_rad)))
        inputs = load_inputs(args.trial, load_session(model_path=model_file))
        zl = reconstruct(inputs.model, inputs.protocol, inputs.targets, method="pf")
        per = lag_and_error(got.q_rad, zl.q_rad, trial.rate_hz, solved)
        report["replay"] = {"trial": Path(args.trial).name, "frames": int(got.n_frames), "markers": len(trial.labels),
                            "stream_stdout": stream.stdout.strip(), "live_summary": out.strip().splitlines()[:4],
                            "max_abs_diff_to_offline_causal_on_recording_rad": d_rec,
                            "max_abs_diff_to_offline_causal_on_trial_file_rad": d_file,
                            "vs_zero_lag": {names[j]: v for j, v in per.items()}}
        print(f"{Path(args.trial).name}: {got.n_frames} frames via exubio stream | exubio live (127.0.0.1)")
        print(f"  max |live - offline causal| = {d_rec:.2e} rad (on the recorded markers), {d_file:.2e} rad (on the "
              "trial file: mm over the wire)")
        print("  live (causal, no filter) vs offline zero-lag PF, per coordinate:")
        print(f"  {'coordinate':24s} {'RMSE deg':>9s} {'max deg':>8s} {'lag ms':>7s} {'RMSE after lag':>15s}")
        for j, v in per.items():
            print(f"  {names[j]:24s} {v['rmse_deg']:9.2f} {v['max_deg']:8.2f} {v['lag_ms']:7.1f} "
                  f"{v['rmse_after_shift_deg']:15.2f}")

        # 2. the lag of each causal choice
        example = ROOT / "exubio" / "data" / "example_abduction.c3d"
        from exubio.io.results import read_angles_csv

        _, tnames, q_true = read_angles_csv(example.with_name("example_abduction.truth.csv"))  # rad
        gm, gp = load_model_and_protocol()
        q_true = q_true[:, [list(tnames).index(n) for n in gm.coordinate_names]]
        ex_trial = read_trial(example)
        ex_solved = [j for j, e in enumerate(bind(gm, gp).not_solved) if not e]
        ex_zl = reconstruct(*_inputs(example, load_inputs), method="pf")
        rows = []
        for cutoff in (None, 12.0, 8.0, 6.0, 4.0):
            opts = LiveOptions(causal=CausalOptions(cutoff_hz=cutoff))
            real = reconstruct_causal(trial, model, protocol, options=opts)
            r = lag_and_error(real.q_rad, zl.q_rad, trial.rate_hz, solved)
            ex = reconstruct_causal(ex_trial, gm, gp, options=opts)
            e = lag_and_error(ex.q_rad, q_true, ex_trial.rate_hz, ex_solved)
            ez = lag_and_error(ex_zl.q_rad, q_true, ex_trial.rate_hz, ex_solved)
            row = {"filter": "none" if cutoff is None else f"{cutoff:g} Hz",
                   "real_lag_ms_median": float(np.median([v["lag_ms"] for v in r.values()])),
                   "real_rmse_vs_zero_lag_deg_median": float(np.median([v["rmse_deg"] for v in r.values()])),
                   "real_rmse_vs_zero_lag_deg_max": float(max(v["rmse_deg"] for v in r.values())),
                   "real_mean_residual_mm": float(np.nanmean(real.residuals_m) * 1e3),
                   "sim_lag_ms_median": float(np.median([v["lag_ms"] for v in e.values()])),
                   "sim_rmse_vs_truth_deg_median": float(np.median([v["rmse_deg"] for v in e.values()])),
                   "sim_rmse_vs_truth_deg_max": float(max(v["rmse_deg"] for v in e.values())),
                   "sim_zero_lag_rmse_vs_truth_deg_max": float(max(v["rmse_deg"] for v in ez.values()))}
            rows.append(row)
        report["choices"] = rows
        print("\n  causal choice | real: lag ms (median coord), RMSE vs zero-lag deg (median / max), residual mm | "
              "simulated: lag ms, RMSE vs truth deg (median / max; zero-lag offline max)")
        for r in rows:
            print(f"  {r['filter']:>6s} | {r['real_lag_ms_median']:5.1f}  {r['real_rmse_vs_zero_lag_deg_median']:5.2f} / "
                  f"{r['real_rmse_vs_zero_lag_deg_max']:5.2f}  {r['real_mean_residual_mm']:5.2f} | "
                  f"{r['sim_lag_ms_median']:5.1f}  {r['sim_rmse_vs_truth_deg_median']:5.2f} / {r['sim_rmse_vs_truth_deg_max']:5.2f} "
                  f"({r['sim_zero_lag_rmse_vs_truth_deg_max']:.2f})")
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1))
    return 0


def _inputs(path, load_inputs):
    inp = load_inputs(path)
    return inp.model, inp.protocol, inp.targets


if __name__ == "__main__":
    sys.exit(main())
