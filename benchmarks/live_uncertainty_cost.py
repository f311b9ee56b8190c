"""What one frame's angle uncertainties cost, as a live session would have to compute them: the
assessment's arithmetic (exubio.trust.observability.angle_determinacy, with the run's STA amplitude
model and the frame's marker residuals) on a single frame, at each of the protocol's reference
postures; against the 1 ms (1000 Hz) and 5 ms (200 Hz) a live frame has. Prints the median, the
quartiles and the maximum over the postures, each the median of --repeats calls.

    python benchmarks/live_uncertainty_cost.py [--protocol upper_limb_21] [--repeats 20]
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--protocol", default="upper_limb_21")
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args(argv)

    from exubio.api import load_model, load_protocol
    from exubio.protocol.bind import bind
    from exubio.trust.assess import reference_postures_of
    from exubio.trust.observability import angle_determinacy
    from exubio.trust.sta_amplitude import amplitude_of

    model = load_model()
    protocol = load_protocol(args.protocol, model=model)
    b = bind(model, protocol)
    postures = reference_postures_of(b)
    k = len(protocol.markers)
    present, residuals = np.ones((1, k), bool), np.full((1, k), 0.002)  # 2 mm: a typical live residual
    amp = amplitude_of(b)

    def one(q):
        return angle_determinacy(b.kin, b.points, q[None], present, protocol.weights, held=b.held, locked=b.locked,
                                 amplitude=amp, residuals_m=residuals)

    one(postures[0])  # warm-up: imports, compiled kernels
    per_posture = []
    for q in postures:
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            one(q)
            times.append(time.perf_counter() - t)
        per_posture.append(1e3 * float(np.median(times)))
    x = np.array(per_posture)
    print(f"one frame's angle uncertainties ({protocol.name}, {len(x)} reference postures, median of {args.repeats} "
          f"calls each; load average {os.getloadavg()[0]:.2f}):")
    print(f"  median {np.median(x):.2f} ms, quartiles {np.percentile(x, 25):.2f}-{np.percentile(x, 75):.2f} ms, "
          f"max {x.max():.2f} ms; a live frame has 1 ms at 1000 Hz, 5 ms at 200 Hz")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
