"""The profile's peak finder against scipy.signal.find_peaks, the implementation it stands in for."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import find_peaks as scipy_find_peaks

from swarmpose.detect.peaks import find_peaks


@pytest.mark.parametrize("seed", range(60))
def test_the_same_peaks_and_prominences_as_scipy(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 80))
    x = rng.normal(size=n).cumsum()
    if seed % 3 == 0:
        x = np.round(x, 0)  # flat tops and flat valleys
    prominence, distance = float(rng.uniform(0.0, 2.0)), int(rng.integers(1, 8))
    peaks, values = find_peaks(x, prominence, distance)
    expected, props = scipy_find_peaks(x, prominence=prominence, distance=distance)
    np.testing.assert_array_equal(peaks, expected)
    np.testing.assert_allclose(values, props["prominences"])


def test_a_head_profile_by_hand():
    profile = np.array([0.0, 1.0, 1.7, 1.2, 1.1, 1.6, 1.6, 1.0, 0.0])  # two heads, the right one a flat top
    peaks, values = find_peaks(profile, prominence=0.3)
    assert peaks.tolist() == [2, 5] and values == pytest.approx([1.7, 0.5])  # the highest: down to both ends
    assert find_peaks(profile, prominence=0.3, distance=4)[0].tolist() == [2]  # too close: the lower goes
