"""Ground truth written by ``swarmpose synth`` beside a sequence (``groundtruth.jsonl``).

One JSON object per frame: ``frame``, ``timestamp_ns``, ``pose`` (36,), ``joints3d`` and
``joints2d`` (evaluation joints, camera frame metres / pixels) and ``detections`` (the
simulated detector's keypoints, ``{"layout": name, "keypoints": {name: [x, y, score]}}``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS, LAYOUTS
from swarmpose.core.errors import AssetError

GROUND_TRUTH_FILE = "groundtruth.jsonl"


@dataclass(frozen=True)
class GroundTruth:
    """A sequence's ground truth, indexed by frame number.

    poses: (F, 36); joints3d: (F, J, 3) metres, camera frame, in ``EVAL_JOINTS`` order
    (NaN where a record lacks a joint); detections: per frame the simulated detector's
    (layout name, (K, 3) keypoints) recorded at synth time, or None; points2d: per frame
    the true pixel positions (2,) of body points (name -> px), from which the simulated
    detector draws keypoints where none were recorded (empty: none).
    """

    frames: tuple[int, ...]
    poses: np.ndarray
    joints3d: np.ndarray
    detections: tuple[tuple[str, np.ndarray] | None, ...]
    points2d: tuple[dict[str, np.ndarray], ...] = ()

    @cached_property
    def _rows(self) -> dict[int, int]:
        return {f: i for i, f in enumerate(self.frames)}

    def row(self, frame: int) -> int:
        """Row of frame number ``frame``; KeyError if the sequence has no ground truth for it."""
        return self._rows[frame]


def load_ground_truth(folder: Path) -> GroundTruth | None:
    """Read ``folder/groundtruth.jsonl``; None when the folder has none. AssetError names a bad line."""
    path = Path(folder) / GROUND_TRUTH_FILE
    if not path.exists():
        return None
    frames, poses, joints, dets = [], [], [], []
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                frames.append(int(rec["frame"]))
                poses.append(np.asarray(rec["pose"], dtype=np.float64))
                j3 = rec.get("joints3d", {})
                joints.append([j3.get(j, [np.nan] * 3) for j in EVAL_JOINTS])
                det = rec.get("detections")
                if det:
                    layout = LAYOUTS[det["layout"]]
                    kp = np.array([det["keypoints"].get(k, [0.0, 0.0, 0.0]) for k in layout.keypoints], float)
                    dets.append((layout.name, kp))
                else:
                    dets.append(None)
            except (ValueError, KeyError, TypeError) as exc:
                raise AssetError(f"{path}:{lineno}: not a ground-truth record ({exc}); "
                                 "re-run `swarmpose synth` to rewrite the sequence") from exc
    joints3d = np.array(joints, float).reshape(-1, len(EVAL_JOINTS), 3)
    return GroundTruth(tuple(frames), np.array(poses).reshape(-1, 36), joints3d, tuple(dets))
