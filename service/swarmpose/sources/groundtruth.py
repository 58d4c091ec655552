"""Ground truth written by ``swarmpose synth`` beside a sequence (``groundtruth.jsonl``).

One JSON object per frame: ``frame``, ``timestamp_ns``, ``pose`` (36,), ``joints3d`` and
``joints2d`` (evaluation joints, camera frame metres / pixels) and ``detections`` (the
simulated detector's keypoints, ``{"layout": name, "keypoints": {name: [x, y, score]}}``).
A sequence of several people keeps person 1's fields at the top and adds ``people``: per
person ``id``, ``pose``, ``joints3d``, ``joints2d``, ``detections``, ``visible`` (0..1),
``box`` ([x0, y0, x1, y1] px or null) and ``occluded`` (evaluation joints hidden by
another person). Single-person files have no ``people``.
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
class PersonTruth:
    """One person of one frame of a multi-person sequence.

    id: the person's id (1..P, stable over the sequence); pose: (36,) camera frame;
    joints3d: (J, 3) m and joints2d: (J, 2) px in ``EVAL_JOINTS`` order (NaN where the
    record lacks a joint); detection: the simulated detector's (layout name, (K, 3)
    keypoints x px, y px, score) or None; visible: share (0..1) of the person's silhouette
    not hidden by other people; box: (4,) [x0, y0, x1, y1] px (inclusive) of its visible
    pixels, or None when none is visible; occluded: (J,) bool, evaluation joints hidden by
    another person.
    """

    id: int
    pose: np.ndarray
    joints3d: np.ndarray
    joints2d: np.ndarray
    detection: tuple[str, np.ndarray] | None
    visible: float
    box: np.ndarray | None
    occluded: np.ndarray


@dataclass(frozen=True)
class GroundTruth:
    """A sequence's ground truth, indexed by frame number.

    poses: (F, 36); joints3d: (F, J, 3) metres, camera frame, in ``EVAL_JOINTS`` order
    (NaN where a record lacks a joint); detections: per frame the simulated detector's
    (layout name, (K, 3) keypoints) recorded at synth time, or None; points2d: per frame
    the true pixel positions (2,) of body points (name -> px), from which the simulated
    detector draws keypoints where none were recorded (empty: none). These fields describe
    person 1. people: per frame every person of a multi-person sequence (person 1 first;
    its fields equal the ones above), an empty tuple per frame for single-person files
    (empty altogether for ground truth that is not from ``swarmpose synth``).
    """

    frames: tuple[int, ...]
    poses: np.ndarray
    joints3d: np.ndarray
    detections: tuple[tuple[str, np.ndarray] | None, ...]
    points2d: tuple[dict[str, np.ndarray], ...] = ()
    people: tuple[tuple[PersonTruth, ...], ...] = ()

    @cached_property
    def _rows(self) -> dict[int, int]:
        return {f: i for i, f in enumerate(self.frames)}

    def row(self, frame: int) -> int:
        """Row of frame number ``frame``; KeyError if the sequence has no ground truth for it."""
        return self._rows[frame]

    def people_at(self, row: int) -> tuple[PersonTruth, ...]:
        """The people recorded at ``row`` (empty for single-person ground truth)."""
        return self.people[row] if self.people else ()


def _detection(det: dict | None) -> tuple[str, np.ndarray] | None:
    if not det:
        return None
    layout = LAYOUTS[det["layout"]]
    return layout.name, np.array([det["keypoints"].get(k, [0.0, 0.0, 0.0]) for k in layout.keypoints], float)


def _joints(record: dict, key: str, dims: int) -> np.ndarray:
    found = record.get(key, {})
    return np.array([found.get(j, [np.nan] * dims) for j in EVAL_JOINTS], float).reshape(len(EVAL_JOINTS), dims)


def _person(entry: dict) -> PersonTruth:
    box = entry.get("box")
    occluded = set(entry.get("occluded", ()))
    unknown = occluded - set(EVAL_JOINTS)
    if unknown:
        raise ValueError(f"unknown occluded joints {sorted(unknown)}")
    visible = float(entry["visible"])
    if not 0.0 <= visible <= 1.0:
        raise ValueError(f"visible {visible} outside 0..1")
    return PersonTruth(
        id=int(entry["id"]), pose=np.asarray(entry["pose"], dtype=np.float64).reshape(36),
        joints3d=_joints(entry, "joints3d", 3), joints2d=_joints(entry, "joints2d", 2),
        detection=_detection(entry.get("detections")), visible=visible,
        box=None if box is None else np.asarray(box, dtype=np.float64).reshape(4),
        occluded=np.array([j in occluded for j in EVAL_JOINTS]))


def load_ground_truth(folder: Path) -> GroundTruth | None:
    """Read ``folder/groundtruth.jsonl``; None when the folder has none. AssetError names a bad line."""
    path = Path(folder) / GROUND_TRUTH_FILE
    if not path.exists():
        return None
    frames, poses, joints, dets, people = [], [], [], [], []
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                frame = int(rec["frame"])
                pose = np.asarray(rec["pose"], dtype=np.float64).reshape(36)
                joint_row = _joints(rec, "joints3d", 3)
                det = _detection(rec.get("detections"))
                persons = tuple(_person(entry) for entry in rec.get("people", ()))
                if len({p.id for p in persons}) != len(persons):
                    raise ValueError(f"repeated person ids {[p.id for p in persons]}")
            except (ValueError, KeyError, TypeError, AttributeError) as exc:
                raise AssetError(f"{path}:{lineno}: not a ground-truth record ({exc}); "
                                 "re-run `swarmpose synth` to rewrite the sequence") from exc
            frames.append(frame)
            poses.append(pose)
            joints.append(joint_row)
            dets.append(det)
            people.append(persons)
    joints3d = np.array(joints, float).reshape(-1, len(EVAL_JOINTS), 3)
    return GroundTruth(tuple(frames), np.array(poses).reshape(-1, 36), joints3d, tuple(dets), people=tuple(people))
