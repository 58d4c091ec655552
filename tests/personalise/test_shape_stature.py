"""The stature term of the shape fit (:mod:`swarmpose.personalise.shape_stature`): the band by hand,
and the stature measured on a synthetic walk's samples against the subject's true height."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MAKEHUMAN, makehuman_walk

from swarmpose.personalise.shape_stature import BAND, measured_stature, stature_energy


def test_stature_energy_by_hand():
    """1 per cm outside [H (1 - 0.3 %), H (1 + 1.5 %)], nothing inside or without a measure."""
    assert BAND == (-0.003, 0.015)
    measured = 1.70  # the band: 1.6949 .. 1.7255 m
    assert stature_energy(1.70, measured) == 0.0
    assert stature_energy(1.725, measured) == 0.0
    assert stature_energy(1.74, measured) == pytest.approx(1.45)
    assert stature_energy(1.69, measured) == pytest.approx(0.49)
    assert stature_energy(1.69, measured, weight=2.0) == pytest.approx(0.98)
    assert stature_energy(1.50, None) == 0.0
    assert stature_energy(1.50, measured, weight=0.0) == 0.0


@pytest.fixture(scope="module")
def walk_samples(tmp_path_factory):
    """A MakeHuman female-slim subject (1.605 m) walking CMU 131_01 at 3 m, 16 frames, tracked with
    the simulated detector's joints by the default MakeHuman body (1.75 m) as a fit's samples are:
    (samples, the tracking body, the subject's body, camera)."""
    from swarmpose.body.loader import load_body
    from swarmpose.detect.registry import make_detector
    from swarmpose.personalise.personalise import ShapeSample
    from swarmpose.sources.registry import open_source
    from swarmpose.tracking.body_tracker import BodyTracker
    from swarmpose.tracking.config import TrackerConfig

    out = makehuman_walk(tmp_path_factory, "female-slim", 16)
    source = open_source(str(out))
    detector = make_detector("simulated", source)
    tracker = None
    samples = []
    for frame in source:
        tracker = tracker or BodyTracker(load_body(f"makehuman:{MAKEHUMAN}"), frame.intrinsics,
                                         TrackerConfig(particles=24, generations=24))
        joints = detector.detect(frame, None)
        samples.append(ShapeSample(frame, joints, np.asarray(tracker.step(frame, joints).pose, float)))
    return samples, tracker.body, load_body(f"makehuman:{MAKEHUMAN}", "female-slim"), source.intrinsics


@pytest.mark.slow
def test_the_measured_stature_bounds_the_subjects_height(walk_samples):
    """Oracle: the subject's true height lies inside the term's band around the median stature
    measured at the tracked samples (the tracking body only says where to look: it is 15 cm taller),
    and at least 5 of the 16 frames are measured (7 when written)."""
    samples, body, subject, camera = walk_samples
    stature, frames = measured_stature(samples, body, camera, min_score=0.3)
    assert frames >= 5
    assert stature * (1 + BAND[0]) <= subject.height <= stature * (1 + BAND[1]), (stature, subject.height)


def test_no_stature_where_no_knee_is_straight(walk_samples):
    """The same frames with each detected knee moved sideways by 0.35 of its thigh's length in
    the image (the knees bent by about 40 degrees): no leg stands straight, nothing is measured;
    the pose is not asked (it was tracked with a body of another size)."""
    from dataclasses import replace

    samples, body, _, camera = walk_samples
    bent = []
    for sample in samples:
        points = list(sample.joints.layout.points)
        keypoints = sample.joints.keypoints.copy()
        for side in ("left", "right"):
            hip, knee = points.index(f"{side}_hip"), points.index(f"{side}_knee")
            keypoints[knee, 0] += 0.35 * np.hypot(*(keypoints[knee, :2] - keypoints[hip, :2]))
        bent.append(replace(sample, joints=replace(sample.joints, keypoints=keypoints)))
    assert measured_stature(bent, body, camera, min_score=0.3)[1] <= 1
