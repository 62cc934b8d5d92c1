"""How the robot sees the moving bin: a delayed, sampled, noisy estimate and a constant-velocity prediction.

The cameras look at the plate, not at the bin, so the bin's estimate is modelled from the ground
truth, as a tracker (a fiducial on the bin, a person tracker, a motion-capture system) would give
it: the bin centre is sampled every 1 / `estimate_rate_hz` s, each sample gets Gaussian noise of
`estimate_noise_m` on x and y and becomes available `estimate_latency_s` later; between updates
the latest estimate holds (zero-order hold). The prediction is constant velocity: a least-squares
line through the last `velocity_window` estimates (against their sampling times), evaluated at the
time asked for and kept inside the scenario's region (the bin is known to stay there).
"""

from __future__ import annotations

import math

import numpy as np

from scenes.moving_bin import BinPath, MovingBinScenario, region


class BinEstimator:
    """The bin estimates of one episode (deterministic given the scenario's seed)."""

    def __init__(self, scenario: MovingBinScenario, path: BinPath, spec) -> None:
        self._s = scenario
        self._path = path
        self._lo, self._hi = region(scenario, spec)
        self._period = 1.0 / scenario.estimate_rate_hz
        self._noise = np.random.default_rng([scenario.seed, 7331])
        self._samples: list[tuple[float, np.ndarray]] = []

    def latest_index(self, t_s: float) -> int:
        """The index of the newest estimate available at t_s (-1 before the first)."""
        return math.floor((t_s - self._s.estimate_latency_s) / self._period + 1e-9)

    def _sample(self, k: int) -> tuple[float, np.ndarray]:
        while len(self._samples) <= k:  # drawn in order, so noise k is the same whoever asks first
            t_k = len(self._samples) * self._period
            xy = self._path.at(t_k)[0] + self._noise.normal(0.0, self._s.estimate_noise_m, 2)
            self._samples.append((t_k, xy))
        return self._samples[k]

    def estimates(self, t_s: float) -> list[tuple[float, np.ndarray]]:
        """The last `velocity_window` estimates available at t_s: (sampling time, xy) each."""
        k = self.latest_index(t_s)
        if k < 0:
            return [self._sample(0)] if t_s >= 0 else []
        return [self._sample(i) for i in range(max(0, k - self._s.velocity_window + 1), k + 1)]

    def _fit(self, t_now_s: float) -> tuple[np.ndarray, np.ndarray, float] | None:
        """The least-squares line through the available estimates: (xy at tm, velocity, tm)."""
        est = self.estimates(t_now_s)
        if not est:
            return None
        if len(est) == 1:
            return est[0][1], np.zeros(2), est[0][0]
        t = np.array([e[0] for e in est])
        P = np.array([e[1] for e in est])
        tm = t.mean()
        v = ((t - tm)[:, None] * (P - P.mean(axis=0))).sum(axis=0) / ((t - tm) ** 2).sum()
        return P.mean(axis=0), v, tm

    def predict(self, t_now_s: float, t_at_s: float) -> np.ndarray:
        """Where the bin centre will be at t_at_s (2,), from the estimates available at t_now_s."""
        fit = self._fit(t_now_s)
        if fit is None:
            return self._path.at(0.0)[0].copy()  # before any estimate: where the bin was placed
        xy, v, tm = fit
        return np.clip(xy + v * (t_at_s - tm), self._lo, self._hi)

    def velocity(self, t_now_s: float) -> np.ndarray:
        """The bin's estimated velocity (2,) m/s from the estimates available at t_now_s."""
        fit = self._fit(t_now_s)
        return np.zeros(2) if fit is None else fit[1].copy()
