"""The part of a skin-marker cluster's motion over its bone that the bone STA model's regression
leaves (``exubio.synth.sta_bone``): measured on held-out tasks, and drawn as a smooth random
process in a simulation.

Measured (``measure_residual``). For each trial, the regression fitted on the OTHER trials predicts
the cluster's six rigid parameters (rotation vector, rad; centroid translation, m; bone frame) from
the trial's drivers; the residual r(t) (n, 6) = data - prediction is what a held-out task shows
beyond the regression's mean course. Pooled over the held-out trials:

* amplitude: the second moment per rad^2 of driver, C = sum_t r r^T / sum_t theta^2 (6 x 6), theta
  the humerus's rotation angle from its start orientation (in the lab for the bone files, whose
  thorax is assumed still; in the thorax for a simulation): the residual grows with the motion away
  from the start posture, where it is zero by construction (the same driver and the same zero
  intercept as the uncertainty's amplitude model, ``exubio.truth.sta_amplitude``);
* temporal correlation: the lag at which the residual's autocorrelation (about zero, each of the six
  components scaled to unit RMS, averaged over components and trials, weighted by frames) first
  falls below 1/e, in seconds (``correlation_time_s``).

Drawn (``draw``): x(t) = theta(t) L z(t), L L^T = C, z six independent unit-variance Gaussian
processes: white noise filtered by a Gaussian kernel of SD ``correlation_time_s * rate / 2`` frames,
whose autocorrelation exp(-lag^2 / (4 sd^2)) is 1/e at ``correlation_time_s`` and whose paths are
smooth (no jump from one frame to the next, as a skin cluster has none).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from exubio.errors import InputError

__all__ = ["ResidualProcess", "measure_residual", "correlation_time", "smooth_unit_noise", "MEASURED_HOW"]

MEASURED_HOW = ("leave one task out: for each trial, the rigid regression fitted on the other trials, its residual "
                "(data - prediction) on the held-out trial; pooled over the held-out trials. cov_per_rad2: sum r r^T / "
                "sum theta^2 (theta: the humerus's rotation angle from its start orientation, rad); correlation_time_s: "
                "the lag where the residual's autocorrelation (about zero, each component at unit RMS, averaged) first "
                "falls below 1/e")
PROCESS = ("x(t) = theta(t) L z(t), L L^T = cov_per_rad2; z: independent unit-variance Gaussian white noise filtered "
           "by a Gaussian kernel of SD correlation_time_s * rate / 2 frames (autocorrelation 1/e at correlation_time_s)")
OUTPUTS = ("rotation_x_rad", "rotation_y_rad", "rotation_z_rad", "translation_x_m", "translation_y_m", "translation_z_m")


@dataclass(frozen=True)
class ResidualProcess:
    """``cov_per_rad2`` (6, 6): the held-out residual's second moment (rotation vector rad,
    translation m) per rad^2 of the humerus's rotation; ``correlation_time_s``; ``measured``: how
    (tasks, frames) in words and numbers."""

    cov_per_rad2: np.ndarray
    correlation_time_s: float
    measured: Mapping[str, object]

    @property
    def sd_per_rad(self) -> np.ndarray:
        """(6,) the residual's RMS per component per rad of the humerus's rotation."""
        return np.sqrt(np.clip(np.diag(self.cov_per_rad2), 0.0, None))

    def to_json(self) -> dict:
        return {"outputs": list(OUTPUTS), "cov_per_rad2": [[float(f"{x:.6g}") for x in row] for row in self.cov_per_rad2],
                "sd_per_rad": [float(f"{x:.6g}") for x in self.sd_per_rad],
                "correlation_time_s": round(float(self.correlation_time_s), 4),
                "driver": "humerus_rotation: the humerus's rotation angle from its start orientation (rad)",
                "process": PROCESS, "how": MEASURED_HOW, "measured": dict(self.measured)}

    @classmethod
    def from_json(cls, data: Mapping, /, *, where: str) -> "ResidualProcess":
        try:
            C = np.asarray(data["cov_per_rad2"], dtype=float)
            tau = float(data["correlation_time_s"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: 'residual' needs cov_per_rad2 (6 x 6) and correlation_time_s ({exc})") from None
        if C.shape != (6, 6) or not np.isfinite(C).all() or np.linalg.eigvalsh((C + C.T) / 2).min() < -1e-12 * max(
                1.0, float(np.abs(C).max())):
            raise InputError(f"{where}: 'residual.cov_per_rad2' must be a symmetric positive semi-definite 6 x 6 "
                             f"matrix, got shape {C.shape}")
        if not (np.isfinite(tau) and tau >= 0):
            raise InputError(f"{where}: 'residual.correlation_time_s' must be >= 0 s, got {tau}")
        return cls((C + C.T) / 2, tau, dict(data.get("measured", {})))

    def draw(self, theta: np.ndarray, rate_hz: float, rng: np.random.Generator, /) -> np.ndarray:
        """One draw (n, 6) of the residual for the humerus rotation ``theta`` (n,) rad sampled at
        ``rate_hz`` (module docstring)."""
        theta = np.asarray(theta, dtype=float)
        z = smooth_unit_noise(theta.shape[0], 6, self.correlation_time_s * rate_hz, rng)
        w, V = np.linalg.eigh(self.cov_per_rad2)
        L = V * np.sqrt(np.clip(w, 0.0, None))
        return theta[:, None] * (z @ L.T)


def smooth_unit_noise(n: int, k: int, correlation_frames: float, rng: np.random.Generator, /) -> np.ndarray:
    """(n, k) independent stationary Gaussian processes of unit variance whose autocorrelation is
    exp(-lag^2 / correlation_frames^2) (1/e at ``correlation_frames``): white noise filtered by a
    Gaussian kernel of SD correlation_frames / 2, normalised to unit energy."""
    sd = float(correlation_frames) / 2.0
    if sd < 0.5:
        return rng.standard_normal((n, k))
    half = int(np.ceil(4.0 * sd))
    lags = np.arange(-half, half + 1)
    kern = np.exp(-0.5 * (lags / sd) ** 2)
    kern /= np.sqrt(np.sum(kern ** 2))
    w = rng.standard_normal((n + 2 * half, k))
    out = np.empty((n, k))
    for j in range(k):
        out[:, j] = np.convolve(w[:, j], kern, mode="valid")
    return out


def _acf(r: np.ndarray, max_lag: int) -> np.ndarray:
    """(max_lag + 1,) autocorrelation about zero of r (n, c), each component at unit RMS, averaged."""
    s = np.sqrt(np.mean(r * r, axis=0))
    z = r[:, s > 0] / s[s > 0]
    n = z.shape[0]
    return np.array([np.mean(np.sum(z[: n - L] * z[L:], axis=0) / np.sum(z * z, axis=0)) if L < n else np.nan
                     for L in range(max_lag + 1)])


def correlation_time(residuals: Sequence[np.ndarray], rate_hz: float, /) -> float:
    """Seconds: the lag where the frame-weighted mean autocorrelation of ``residuals`` (each (n, c),
    NaN frames dropped) first falls below 1/e (linear interpolation between frames)."""
    rs = [r[np.isfinite(r).all(axis=1)] for r in residuals]
    rs = [r for r in rs if r.shape[0] > 2]
    if not rs:
        raise InputError("no residual long enough to measure a correlation time")
    max_lag = min(r.shape[0] for r in rs) - 1
    w = np.array([r.shape[0] for r in rs], dtype=float)
    acf = np.sum([wi * _acf(r, max_lag) for wi, r in zip(w, rs)], axis=0) / w.sum()
    below = np.flatnonzero(acf < np.exp(-1.0))
    if below.size == 0:
        return max_lag / rate_hz
    L = int(below[0])
    a0, a1 = acf[L - 1], acf[L]
    return (L - 1 + (a0 - np.exp(-1.0)) / (a0 - a1)) / rate_hz


def measure_residual(residuals: Sequence[np.ndarray], thetas: Sequence[np.ndarray], rate_hz: float, /, *,
                     tasks: Sequence[str] = ()) -> ResidualProcess:
    """The process (module docstring) from held-out residuals (each (n, 6)) and the humerus's
    rotation (each (n,) rad) of the same frames, all sampled at ``rate_hz``."""
    if len(residuals) != len(thetas) or not residuals:
        raise InputError("measure_residual needs one humerus rotation per held-out residual, and at least one")
    num, den, frames = np.zeros((6, 6)), 0.0, 0
    for r, th in zip(residuals, thetas):
        ok = np.isfinite(r).all(axis=1) & np.isfinite(th)
        num += r[ok].T @ r[ok]
        den += float(np.sum(th[ok] ** 2))
        frames += int(ok.sum())
    if den <= 0:
        raise InputError("the held-out trials hold no motion of the humerus from its start: no residual amplitude")
    tau = correlation_time(list(residuals), rate_hz)
    C = num / den
    return ResidualProcess(C, tau, {"tasks": list(tasks), "frames": frames, "sampling_rate_hz": rate_hz,
                                    "rms_rotation_deg": round(float(np.degrees(np.sqrt(np.trace(C[:3, :3]) * den / frames))), 3),
                                    "rms_translation_mm": round(float(1e3 * np.sqrt(np.trace(C[3:, 3:]) * den / frames)), 3)})
