"""Building the protocol's messages (``protocol/*.schema.json``) from plain values.

* ``swarmpose.frame`` — one processed frame with every tracked body (:func:`frame_message`,
  each body from :func:`body_message`);
* ``swarmpose.status`` — the worker's health, about once a second (built by
  :mod:`swarmpose.pipeline.status`);
* ``swarmpose.info`` — what a worker tracks and how to read it (:func:`info_message`).

Units: metres (the camera frame, OpenCV axes, or the floor-aligned world frame of
:mod:`swarmpose.core.world`, as a frame message's ``coordinates`` says), pixels, nanoseconds,
milliseconds for durations, radians for angles. Nothing here knows the tracker: callers pass arrays.
"""

from __future__ import annotations

import platform
from collections.abc import Mapping
from importlib import metadata

import numpy as np

from swarmpose import __version__
from swarmpose.body.joint_set import (
    SKELETON_INDEX,
    SKELETON_LINKS,
    SKELETON_NAMES,
    SKELETON_PARENTS,
    skeleton_confidence,
)
from swarmpose.body.skeleton import ANGLE_LIMITS, ANGLE_NAMES, EVAL_JOINTS
from swarmpose.core.errors import check_shape
from swarmpose.core.world import matrix_rows
from swarmpose.messages.schema import MESSAGE_VERSIONS, PROTOCOL_VERSION, keys

POSE_NAMES: tuple[str, ...] = ("tx", "ty", "tz", "qw", "qx", "qy", "qz") + ANGLE_NAMES
"""Names of the 36 entries of the pose vector h."""
CAMERA_FRAME = "camera (OpenCV: x right, y down, z forward)"
WORLD_FRAME = ("world (floor-aligned: y up, floor at y = 0, x = the camera's x on the floor, z = x cross y; "
               "origin on the floor under the first tracked person's start); camera until known: see each "
               "frame's coordinates")
ORIENTATION = ("orientation_xyzw: the unit quaternion [x, y, z, w] (w >= 0) turning the joint's own axes into the "
               "message's coordinates; the joint's axes are the body's T-pose axes (x = the subject's left, "
               "y = up, z = forward) carried along by the joint rotations from the pelvis down to the joint's "
               "bone (docs/conventions.md)")


def json_vector(v: np.ndarray, digits: int) -> list[float] | None:
    """A vector as a JSON list rounded to ``digits`` decimals, or None when any entry is not finite."""
    return [round(float(x), digits) for x in v] if np.all(np.isfinite(v)) else None


def json_rows(values: np.ndarray, digits: int) -> list[list[float] | None]:
    """Each row of ``values`` (K, D) as a JSON list rounded to ``digits`` decimals, None for a row
    with an entry that is not finite (:func:`json_vector` of each row, in one pass)."""
    finite = np.all(np.isfinite(values), axis=1)
    return [row if ok else None for row, ok in zip(np.round(values, digits).tolist(), finite.tolist())]


def full_joint_arrays(joints3d: np.ndarray, joints2d: np.ndarray, confidence: np.ndarray,
                      skeleton: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, ...]:
    """The full joint set's positions (K, 3), pixels (K, 2), confidences (K,) and orientations (K, 4)
    (``SKELETON_NAMES`` order, NaN where unknown) from the 14 evaluation joints' ``joints3d``,
    ``joints2d`` and ``confidence`` and the pose's ``skeleton`` (see :func:`body_message`)."""
    n = len(SKELETON_NAMES)
    positions, pixels, orientations = np.full((n, 3), np.nan), np.full((n, 2), np.nan), np.full((n, 4), np.nan)
    full_confidence = np.zeros(n)
    if skeleton is not None:
        positions, pixels, orientations = (np.array(a, dtype=np.float64) for a in skeleton)
        check_shape("skeleton positions", positions, (n, 3))
        check_shape("skeleton pixels", pixels, (n, 2))
        check_shape("skeleton orientations", orientations, (n, 4))
        full_confidence = skeleton_confidence(confidence)
    for e, name in enumerate(EVAL_JOINTS):  # the 14 as given, whatever the skeleton says
        k = SKELETON_INDEX[name]
        positions[k], pixels[k], full_confidence[k] = joints3d[e], joints2d[e], confidence[e]
    return positions, pixels, full_confidence, orientations


def body_message(body_id: int, state: str, reason: str, pose: np.ndarray | None, joints3d: np.ndarray,
                 joints2d: np.ndarray, confidence: np.ndarray, objective: Mapping[str, float],
                 detection: dict | None = None, velocities: np.ndarray | None = None,
                 skeleton: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> dict:
    """One body of a frame message: every joint of ``SKELETON_NAMES`` (K = 28).

    pose: (36,) or None; joints3d: (14, 3) m and joints2d: (14, 2) px in ``EVAL_JOINTS``
    order (NaN rows where unknown); confidence: (14,) 0..1; objective: E and its terms;
    detection: ``{"layout", "keypoints": {name: [x, y, score]}}`` the body was fitted to;
    velocities: (14, 3) m/s of the joints (None, or a joint's non-finite row: no ``velocity_m_s``);
    skeleton: the full joint set of the pose, ``(positions (K, 3) m, pixels (K, 2) px, orientations
    (K, 4) unit quaternions [x, y, z, w])`` in ``SKELETON_NAMES`` order, or None (no pose: the joints
    beyond the 14 are null with confidence 0, and no joint has an orientation). The 14 evaluation
    joints take their position, pixel and confidence from ``joints3d``, ``joints2d`` and
    ``confidence``; the others take the skeleton's positions and the mean confidence of the
    evaluation joints they follow (:func:`~swarmpose.body.joint_set.skeleton_confidence`).
    """
    positions, pixels, full_confidence, orientations = full_joint_arrays(joints3d, joints2d, confidence, skeleton)
    rounded_confidence = np.round(np.clip(full_confidence, 0.0, 1.0), 3).tolist()
    joints = {name: {"position_m": p3, "orientation_xyzw": q, "pixel": p2, "confidence": c}
              for name, p3, q, p2, c in zip(SKELETON_NAMES, json_rows(positions, 6), json_rows(orientations, 6),
                                            json_rows(pixels, 2), rounded_confidence)}
    if velocities is not None:
        for name, v in zip(EVAL_JOINTS, velocities):
            if joints[name]["position_m"] is not None and np.all(np.isfinite(v)):
                joints[name]["velocity_m_s"] = json_vector(v, 4)
    message = {"id": int(body_id), "state": state, "reason": reason,
               "pose": None if pose is None else [round(float(x), 6) for x in pose],
               "joints": joints,
               "objective": {k: round(float(v), 4) for k, v in objective.items() if np.isfinite(v)}}
    if detection is not None:
        message["detection"] = detection
    return message


def frame_message(camera: str, frame: int, capture_ns: int, received_ns: int, publish_ns: int,
                  bodies: list[dict], reason: str = "", timings_ms: Mapping[str, float] | None = None,
                  coordinates: str = "camera", camera_to_world: np.ndarray | None = None) -> dict:
    """A ``swarmpose.frame`` message (see ``protocol/frame.schema.json``). coordinates: the frame
    of the bodies' ``position_m`` and ``pose`` (``camera`` or ``world``); camera_to_world: the
    camera's (4, 4) transform into the world frame where known, else None."""
    message = {"schema": "swarmpose.frame", "version": MESSAGE_VERSIONS["frame"], "camera": camera, "frame": int(frame),
               "capture_ns": int(capture_ns), "received_ns": int(received_ns), "publish_ns": int(publish_ns),
               "latency_ms": round(max(publish_ns - received_ns, 0) / 1e6, 3), "reason": reason,
               "coordinates": coordinates, "camera_to_world": matrix_rows(camera_to_world), "bodies": bodies}
    if timings_ms:
        message["timings_ms"] = {k: round(float(v), 2) for k, v in timings_ms.items()}
    return message


def versions() -> dict[str, str]:
    """Versions of swarmpose, the protocol, zenoh and Python."""
    try:
        zenoh_version = metadata.version("eclipse-zenoh")
    except metadata.PackageNotFoundError:
        zenoh_version = "not installed"
    return {"swarmpose": __version__, "protocol": str(PROTOCOL_VERSION), "zenoh": zenoh_version,
            "python": platform.python_version()}


def info_message(camera: str, *, intrinsics=None, body=None, body_spec: str = "", source: str = "",
                 detector: str = "", mode: str = "hybrid", opencl_device: str = "",
                 personalisation: dict | None = None, world: dict | None = None) -> dict:
    """A ``swarmpose.info`` message. intrinsics: :class:`~swarmpose.core.camera.Intrinsics` or None
    (no frame yet); body: the tracking :class:`~swarmpose.body.skinned.SkinnedBody`;
    personalisation: ``{"needed", "bodies"}`` with ``--personalize`` (each body's state), else None;
    world: ``{"coordinates", "floor", "camera_to_world"}`` (:meth:`swarmpose.pipeline.world.WorldFrame.info`),
    None: camera coordinates, no floor."""
    world = world or {"coordinates": "camera", "floor": None, "camera_to_world": None}
    intr = None if intrinsics is None else {
        "width": int(intrinsics.width), "height": int(intrinsics.height), "fx": float(intrinsics.fx),
        "fy": float(intrinsics.fy), "cx": float(intrinsics.cx), "cy": float(intrinsics.cy)}
    body_info = {"spec": body_spec, "name": getattr(body, "name", ""),
                 "height_m": round(float(body.height), 4) if body is not None else 0.0,
                 "bones": len(body.bone_names) if body is not None else 0,
                 "triangles": len(body.triangles) if body is not None else 0}
    if personalisation is not None:
        body_info["personalisation"] = personalisation
    limits = {n: [float(lo), float(hi)] for n, (lo, hi) in zip(ANGLE_NAMES, ANGLE_LIMITS)}
    return {"schema": "swarmpose.info", "version": MESSAGE_VERSIONS["info"], "camera": camera, "keys": keys(camera),
            "skeleton": {"joints": list(SKELETON_NAMES),
                         "parents": [SKELETON_NAMES[p] if p >= 0 else None for p in SKELETON_PARENTS],
                         "links": [list(link) for link in SKELETON_LINKS], "evaluation_joints": list(EVAL_JOINTS),
                         "units": "m", "orientation": ORIENTATION,
                         "frame": WORLD_FRAME if world["coordinates"] == "world" else CAMERA_FRAME},
            "pose_vector": {"names": list(POSE_NAMES), "limits_rad": limits},
            "intrinsics": intr, "body": body_info, "source": source, "detector": detector, "mode": mode,
            "opencl_device": opencl_device, "world": world, "versions": versions()}
