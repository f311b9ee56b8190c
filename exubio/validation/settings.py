"""What the validation study runs: trial lengths and rates, noise and artefact, the sensitivity
grid, which real data to use (``ValidationSettings``), and the short smoke-test variant
(``QUICK_SETTINGS``). Plain data, no solver."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["QUICK_SETTINGS", "ValidationSettings"]


@dataclass(frozen=True)
class ValidationSettings:
    """What the study runs. Durations in s, rates in Hz, noise/STA in mm (STA: peak of every
    humerus marker's artefact, as in exubio.synth.simulate), spring constants in N/m, ratios in s."""

    trial_duration_s: float = 25.0  # simulated abduction / flexion (5 cycles of 5 s, as the paper's trials)
    trial_rate_hz: float = 200.0  # the paper's capture rate
    sier_duration_s: float = 30.0  # the paper's Table 1: 30 s ...
    sier_rate_hz: float = 3200.0  # ... in 96,001 frames (3200 Hz)
    noise_mm: float = 1.0
    sta_mm: float = 20.0  # the paper's artefact reached about 20 mm on its GH marker
    seed: int = 1
    gh_marker: str = "DELT"  # the humerus marker closest to the GH joint (over the deltoid)
    sensitivity_stiffness_n_per_m: tuple[float, ...] = tuple(float(v) for v in np.logspace(1.0, 4.0, 8))
    sensitivity_ratio_s: tuple[float, ...] = (0.01, 0.1, 1.0, 10.0)
    sier_realisations: int = 10  # extra SIER runs with other noise/STA seeds (0, 1, ...): how typical is Fig. 4?
    sier_realisation_rate_hz: float = 200.0
    real_trials: bool = True  # use the real TRC trials for abduction and flexion when available
    c3d_tasks: bool = True  # compare the 21-marker C3D task trials where a plane of elevation matches
    quick: bool = False


QUICK_SETTINGS = ValidationSettings(trial_duration_s=5.0, trial_rate_hz=40.0, sier_duration_s=4.0,
                                    sier_rate_hz=50.0, sier_realisations=2, sier_realisation_rate_hz=50.0,
                                    real_trials=False, c3d_tasks=False, quick=True)
