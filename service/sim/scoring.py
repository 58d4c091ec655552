"""Score frame messages against a sequence's ground truth as they are published (Δ, A(t))."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.sim.evaluate import summarise_frames
from swarmpose.sources.base import Frame
from swarmpose.sources.groundtruth import GroundTruth


class ScoreSink:
    """Keeps the first body's 3D joints of every frame message that has ground truth.

    ``summary()``: :func:`swarmpose.sim.evaluate.summarise` over the frames the run went through
    (a frame without a body or without a joint counts as a miss).
    """

    def __init__(self, ground_truth: GroundTruth):
        self.ground_truth = ground_truth
        self.estimates: dict[int, np.ndarray] = {}

    def frame(self, message: dict, frame: Frame | None) -> None:
        index = message["frame"]
        try:
            self.ground_truth.row(index)
        except KeyError:  # a frame the sequence has no ground truth for
            return
        joints = np.full((len(EVAL_JOINTS), 3), np.nan)
        if message["bodies"]:
            named = message["bodies"][0]["joints"]
            for k, name in enumerate(EVAL_JOINTS):
                p = named.get(name, {}).get("position_m")
                if p is not None:
                    joints[k] = p
        self.estimates[index] = joints

    def status(self, message: dict) -> None:
        """Status messages carry nothing to score."""

    def close(self) -> None:
        """Nothing to release."""

    def summary(self) -> dict:
        """Δ (``mpjpe_mm``), ``A``, ``coverage``, ``frames``, ``per_joint_mm`` of the frames seen."""
        return summarise_frames(self.ground_truth, sorted(self.estimates), self.estimates)
