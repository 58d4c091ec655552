"""The One-Euro filter (Casiez, Roussel and Vogel, CHI 2012) on pose vectors, for the live path.

A first-order low-pass filter whose cut-off frequency rises with the signal's speed: slow
motion (where jitter shows) is smoothed hard, fast motion (where lag shows) is barely
smoothed. Per component, with ``dt`` the time since the previous sample (s)::

    a(f)    = 1 / (1 + 1 / (2 pi f dt))                    smoothing factor of cut-off f (Hz)
    dx      = (x - x_prev_filtered) / dt                  speed
    dx_f    = dx_f_prev + a(d_cutoff_hz) (dx - dx_f_prev)  its low-passed value
    f       = min_cutoff_hz + beta |dx_f|                  the adaptive cut-off, Hz
    x_f     = x_f_prev + a(f) (x - x_f_prev)

``beta`` has the unit s per unit of the component (s/m for a position, s/rad for an angle),
so one ``beta`` serves a pose vector whose positions (m) move about as fast as its angles
(rad) do. The filter is applied to the *published* pose only: the tracker searches around its
unfiltered solution, so a filter's lag never feeds back into the search (the old blend did,
and made the tracking itself worse).
"""

from __future__ import annotations

import math

import numpy as np

from swarmpose.body.skeleton import ROOT_QUATERNION

DEFAULT_DT_S = 1.0 / 30.0
"""Frame period assumed where timestamps do not advance (s)."""


def smoothing_factor(cutoff_hz: np.ndarray | float, dt_s: float) -> np.ndarray | float:
    """The exponential smoothing factor of a first-order low-pass at ``cutoff_hz`` sampled every ``dt_s``."""
    return 1.0 / (1.0 + 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz) * dt_s))


class OneEuroFilter:
    """A One-Euro filter over vectors (every component on its own; see the module doc).

    min_cutoff_hz: the cut-off at rest (lower: less jitter, more lag when slow), Hz;
    beta: how fast the cut-off rises with speed (higher: less lag when fast), s per unit;
    d_cutoff_hz: the cut-off of the speed estimate, Hz.
    """

    def __init__(self, min_cutoff_hz: float, beta: float, d_cutoff_hz: float = 1.0):
        if min_cutoff_hz <= 0 or d_cutoff_hz <= 0 or beta < 0:
            raise ValueError(f"One-Euro filter: cut-offs must be > 0 and beta >= 0, got min_cutoff={min_cutoff_hz}, "
                             f"beta={beta}, d_cutoff={d_cutoff_hz}")
        self.min_cutoff_hz, self.beta, self.d_cutoff_hz = float(min_cutoff_hz), float(beta), float(d_cutoff_hz)
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next sample passes through unchanged."""
        self._value: np.ndarray | None = None
        self._speed: np.ndarray | None = None
        self._time_s = 0.0

    def __call__(self, value: np.ndarray, time_s: float) -> np.ndarray:
        """The filtered value (same shape as ``value``) of a sample taken at ``time_s`` (s)."""
        value = np.asarray(value, dtype=np.float64)
        if self._value is None:
            self._value, self._speed, self._time_s = value.copy(), np.zeros_like(value), float(time_s)
            return value.copy()
        dt = float(time_s) - self._time_s
        if not dt > 0:
            dt = DEFAULT_DT_S
        speed = (value - self._value) / dt
        self._speed = self._speed + smoothing_factor(self.d_cutoff_hz, dt) * (speed - self._speed)
        cutoff = self.min_cutoff_hz + self.beta * np.abs(self._speed)
        self._value = self._value + smoothing_factor(cutoff, dt) * (value - self._value)
        self._time_s = self._time_s + dt
        return self._value.copy()


class PoseFilter(OneEuroFilter):
    """A One-Euro filter of pose vectors h (36,): the root quaternion is kept on the previous
    sample's hemisphere before filtering (q and -q are one rotation) and unit after it."""

    def __call__(self, pose: np.ndarray, time_s: float) -> np.ndarray:
        pose = np.array(pose, dtype=np.float64)
        if self._value is not None and np.dot(pose[ROOT_QUATERNION], self._value[ROOT_QUATERNION]) < 0:
            pose[ROOT_QUATERNION] *= -1.0
        out = super().__call__(pose, time_s)
        out[ROOT_QUATERNION] /= np.linalg.norm(out[ROOT_QUATERNION])
        return out
