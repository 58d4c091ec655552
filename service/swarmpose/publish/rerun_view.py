"""The live 3D view: every frame message and its RGBD frame logged into a rerun recording.

:class:`RerunSink` is a :class:`~swarmpose.publish.sink.Sink`; the recording it logs into
comes from :func:`~swarmpose.publish.rerun_stream.open_stream` (an ``.rrd`` file, a viewer
window, a served or remote viewer). Everything is in the camera frame of the messages
(OpenCV axes: x right, y down, z forward; metres), declared once as ``RDF`` on ``world``.

Entities (:data:`ENTITIES`), per frame on the sequence timeline ``frame`` (the message's
``frame``) and the timeline ``capture`` (its ``capture_ns``: a timestamp when it is a UNIX
time, else a duration since the recording's start):

* ``world``: the frame of the messages' bodies (``coordinates``: the camera frame, OpenCV
  axes ``RDF``; or the floor-aligned world frame, y up, ``RUB``), logged when it changes;
* ``world/camera``: the camera's pose in ``world`` (identity in camera coordinates, the
  message's ``camera_to_world`` in world coordinates), logged when it changes;
* ``world/camera/image``: the pinhole of the intrinsics (static, logged again if they
  change) and the colour image (JPEG); under it per body id N ``bodies/N/joints`` (Points2D
  at the joint pixels, keypoint ids in ``SKELETON_NAMES`` order: the full joint set),
  ``bodies/N/bones`` (LineStrips2D of ``SKELETON_LINKS``) and, where the message has them, the detector's keypoints
  ``bodies/N/detection``;
* ``world/camera/depth``: the depth as a point cloud in the camera frame (m), every
  :data:`DEPTH_STEP`-th pixel in both directions where the depth is valid, coloured from the
  colour image;
* ``world/bodies/N/joints`` (Points3D of the joints' ``position_m``, exactly the message's
  values, keypoint ids as above, the id's colour), ``world/bodies/N/bones`` (LineStrips3D),
  ``world/bodies/N/axes`` (Arrows3D: each joint's frame from its ``orientation_xyzw``, x red, y green,
  z blue, :data:`AXIS_LENGTH_M` long) and ``world/bodies/N/label`` (one point above the head
  labelled ``N state confidence``);
* ``stats/confidence/N`` (Scalars: the body's mean joint confidence, 0..1),
  ``stats/latency_ms`` (Scalars), ``log`` (TextLog: a body's state when it changes, a frame's
  reason, the worker's state when it changes).

A body id that leaves the message is cleared from ``world/bodies`` and the image. Joints
without a position (or pixel) are left out; links touching them too. The 2D skeleton is the
message's ``pixel`` of each joint (the fitted pose projected), so it lies on the image.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarmpose.body.joint_set import SKELETON_LINKS, SKELETON_NAMES
from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.floor import sample_grid
from swarmpose.publish.overlay import id_color
from swarmpose.publish.rerun_stream import Stream, open_stream
from swarmpose.sources.base import Frame

DEPTH_STEP = 3
"""Every DEPTH_STEP-th depth pixel (rows and columns) goes into the point cloud."""
JPEG_QUALITY = 85
EPOCH_NS = 10**18
"""capture_ns at or above this (2001-09-09) is a UNIX time; below, a time since the recording's start."""
AXIS_LENGTH_M = 0.08
"""Length of each joint's axis arrows, m."""
AXIS_COLORS = np.array([[230, 40, 40], [40, 200, 40], [40, 90, 230]], dtype=np.uint8)
"""x red, y green, z blue."""
JOINT_INDEX = {name: k for k, name in enumerate(SKELETON_NAMES)}
LINK_IDS = np.array([(JOINT_INDEX[a], JOINT_INDEX[b]) for a, b in SKELETON_LINKS])
"""(L, 2) keypoint ids of the skeleton's links."""
ENTITIES = ("world", "world/camera", "world/camera/image", "world/camera/depth", "world/bodies/{id}/joints",
            "world/bodies/{id}/bones", "world/bodies/{id}/axes", "world/bodies/{id}/label",
            "world/camera/image/bodies/{id}/joints", "world/camera/image/bodies/{id}/bones", "stats/confidence/{id}",
            "stats/latency_ms", "log")
"""The entity paths the sink logs ({id}: a body id)."""


def depth_points(frame: Frame, step: int = DEPTH_STEP) -> tuple[np.ndarray, np.ndarray | None]:
    """The point cloud of ``frame``: positions (N, 3) float32 m in the camera frame of the
    valid pixels (depth > 0 and finite) of the grid ``depth[::step, ::step]``, row by row,
    and their colours (N, 3) uint8 RGB from the colour image (None without one)."""
    grid = sample_grid(np.asarray(frame.depth), frame.intrinsics, step, np.inf)
    valid = np.isfinite(grid[..., 2])
    points = grid[valid].astype(np.float32)
    colors = None
    if frame.color is not None:
        colors = np.asarray(frame.color)[::step, ::step, :3][valid].astype(np.uint8)
    return points, colors


def joint_arrays(body: dict, field: str) -> tuple[np.ndarray, np.ndarray]:
    """The known joints of one body entry: values (K, 3) or (K, 2) float64 of ``field``
    (``position_m`` or ``pixel``) and their keypoint ids (K,) (indices into ``SKELETON_NAMES``);
    joints whose value is null (or, in a file of an earlier protocol, absent) are left out."""
    joints = body.get("joints") or {}
    ids, values = [], []
    for k, name in enumerate(SKELETON_NAMES):
        value = (joints.get(name) or {}).get(field)
        if value is not None:
            ids.append(k)
            values.append(value)
    width = 3 if field == "position_m" else 2
    return np.asarray(values, dtype=np.float64).reshape(-1, width), np.asarray(ids, dtype=np.int64)


def axis_arrows(body: dict, length: float = AXIS_LENGTH_M) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each joint's frame as three arrows: origins (3M, 3) m (the joint's ``position_m``), vectors
    (3M, 3) m (``length`` along its x, y and z axes, from ``orientation_xyzw``) and colours (3M, 3)
    (:data:`AXIS_COLORS`), for the M joints with both values, in ``SKELETON_NAMES`` order."""
    joints = body.get("joints") or {}
    known = [(j["position_m"], j["orientation_xyzw"]) for j in (joints.get(n) or {} for n in SKELETON_NAMES)
             if j.get("position_m") is not None and j.get("orientation_xyzw") is not None]
    if not known:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    positions = np.asarray([p for p, _ in known], dtype=np.float64)
    xyzw = np.asarray([q for _, q in known], dtype=np.float64)
    axes = quaternion_to_matrix(xyzw[:, [3, 0, 1, 2]])  # (M, 3, 3), columns the joint's axes
    vectors = length * np.swapaxes(axes, 1, 2).reshape(-1, 3)
    return np.repeat(positions, 3, axis=0), vectors, np.tile(AXIS_COLORS, (len(known), 1))


def bone_strips(values: np.ndarray, ids: np.ndarray) -> list[np.ndarray]:
    """Line strips (each (2, D)) of the links of :data:`SKELETON_LINKS` whose two joints are in ``ids``."""
    where = {int(k): i for i, k in enumerate(ids)}
    return [values[[where[a], where[b]]] for a, b in LINK_IDS if a in where and b in where]


def mean_confidence(body: dict) -> float:
    """The mean ``confidence`` (0..1) of a body entry's joints (0 without joints)."""
    values = [float((j or {}).get("confidence", 0.0)) for j in (body.get("joints") or {}).values()]
    return float(np.mean(values)) if values else 0.0


def _body_id(body: dict, k: int) -> int:
    body_id = body.get("id")
    return int(body_id) if isinstance(body_id, (int, np.integer)) and not isinstance(body_id, bool) else k


class RerunSink:
    """Logs frame messages (and their frames) into ``stream`` as the module docstring says.

    depth_step: every how many pixels the depth point cloud takes (1: every pixel).
    """

    def __init__(self, stream: Stream, depth_step: int = DEPTH_STEP) -> None:
        import rerun as rr

        self.rr = rr
        self.stream = stream
        self.rec = stream.recording
        self.depth_step = max(1, int(depth_step))
        self.frames = 0
        self._intrinsics: Intrinsics | None = None
        self._ids: set[int] = set()
        self._states: dict[int, str] = {}
        self._worker_state = ""
        self._epoch: bool | None = None
        self._coordinates: str | None = None
        self._camera_pose: list | None = None
        self._closed = False
        annotation = rr.ClassDescription(info=rr.AnnotationInfo(id=0, label="joint"),
                                         keypoint_annotations=[rr.AnnotationInfo(id=k, label=name)
                                                               for k, name in enumerate(SKELETON_NAMES)])
        self.rec.log("world", rr.AnnotationContext([annotation]), static=True)

    @property
    def paths(self) -> list[Path]:
        """The ``.rrd`` file written, if any (run summaries list it with the other outputs)."""
        return [self.stream.rrd] if self.stream.rrd is not None else []

    def _set_time(self, message: dict) -> None:
        self.rec.set_time("frame", sequence=int(message.get("frame", self.frames)))
        capture = int(message.get("capture_ns", 0))
        if self._epoch is None:
            self._epoch = capture >= EPOCH_NS
        if self._epoch:
            self.rec.set_time("capture", timestamp=np.datetime64(capture, "ns"))
        else:
            self.rec.set_time("capture", duration=np.timedelta64(capture, "ns"))

    def _frames_of(self, message: dict) -> None:
        """The axes of ``world`` and the camera's pose in it, logged when they change."""
        rr = self.rr
        coordinates = "world" if message.get("coordinates") == "world" else "camera"
        if coordinates != self._coordinates:
            self._coordinates = coordinates
            self.rec.log("world", rr.ViewCoordinates.RUB if coordinates == "world" else rr.ViewCoordinates.RDF)
        pose = message.get("camera_to_world") if coordinates == "world" else None
        if pose != self._camera_pose or self.frames == 0:
            self._camera_pose = pose
            matrix = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
            self.rec.log("world/camera", rr.Transform3D(translation=matrix[:3, 3], mat3x3=matrix[:3, :3]))

    def _camera(self, frame: Frame) -> None:
        """The pinhole (static), logged again only when the intrinsics change."""
        k = frame.intrinsics
        if k == self._intrinsics:
            return
        self._intrinsics = k
        pinhole = self.rr.Pinhole(image_from_camera=k.matrix, resolution=[k.width, k.height],
                                  camera_xyz=self.rr.ViewCoordinates.RDF, image_plane_distance=0.5)
        self.rec.log("world/camera/image", pinhole, static=True)

    def _images(self, frame: Frame) -> None:
        rr = self.rr
        if frame.color is not None:
            self.rec.log("world/camera/image", rr.Image(np.ascontiguousarray(frame.color[..., :3], dtype=np.uint8),
                                                        color_model="RGB").compress(jpeg_quality=JPEG_QUALITY))
        points, colors = depth_points(frame, self.depth_step)
        self.rec.log("world/camera/depth", rr.Points3D(points, colors=colors, radii=rr.Radius.ui_points(1.5)))

    def _body(self, body: dict, body_id: int) -> None:
        rr, rec = self.rr, self.rec
        color = id_color(body_id)
        state = str(body.get("state", ""))
        confidence = mean_confidence(body)
        positions, ids = joint_arrays(body, "position_m")
        base = f"world/bodies/{body_id}"
        rec.log(f"{base}/joints", rr.Points3D(positions, keypoint_ids=ids, class_ids=0, colors=color,
                                              radii=0.025, show_labels=False))
        rec.log(f"{base}/bones", rr.LineStrips3D(bone_strips(positions, ids), colors=color, radii=0.012))
        origins, vectors, axis_colors = axis_arrows(body)
        rec.log(f"{base}/axes", rr.Arrows3D(origins=origins, vectors=vectors, colors=axis_colors, radii=0.004))
        up = np.array([0.0, 1.0 if self._coordinates == "world" else -1.0, 0.0])
        top = positions[np.argmax(positions @ up)] if len(positions) else np.zeros(3)
        rec.log(f"{base}/label", rr.Points3D(top[None] + 0.15 * up, colors=color, radii=0.001,
                                             labels=f"{body_id} {state} {confidence:.2f}", show_labels=True))
        pixels, pids = joint_arrays(body, "pixel")
        image = f"world/camera/image/bodies/{body_id}"
        rec.log(f"{image}/joints", rr.Points2D(pixels, keypoint_ids=pids, class_ids=0, colors=color,
                                               radii=rr.Radius.ui_points(4.0), show_labels=False))
        rec.log(f"{image}/bones", rr.LineStrips2D(bone_strips(pixels, pids), colors=color,
                                                  radii=rr.Radius.ui_points(2.0)))
        detection = body.get("detection")
        if detection:
            keypoints = np.asarray(list(detection.get("keypoints", {}).values()), dtype=np.float64).reshape(-1, 3)
            found = keypoints[keypoints[:, 2] > 0]
            rec.log(f"{image}/detection", rr.Points2D(found[:, :2], colors=(255, 255, 255),
                                                      radii=rr.Radius.ui_points(2.5)))
        rec.log(f"stats/confidence/{body_id}", rr.Scalars(confidence))
        if self._states.get(body_id) != state:
            reason = body.get("reason") or ""
            rec.log("log", rr.TextLog(f"person {body_id}: {state}" + (f" ({reason})" if reason else ""),
                                      level="WARN" if state == "lost" else "INFO"))
            self._states[body_id] = state

    def frame(self, message: dict, frame: Frame | None) -> None:
        """Log one frame message (and its frame, when the source delivered one)."""
        rr = self.rr
        self._set_time(message)
        self._frames_of(message)
        if frame is not None:
            self._camera(frame)
            self._images(frame)
        bodies = message.get("bodies") or []
        seen = set()
        for k, body in enumerate(bodies):
            body_id = _body_id(body, k)
            seen.add(body_id)
            self._body(body, body_id)
        for gone in sorted(self._ids - seen):
            self.rec.log(f"world/bodies/{gone}", rr.Clear(recursive=True))
            self.rec.log(f"world/camera/image/bodies/{gone}", rr.Clear(recursive=True))
            self._states.pop(gone, None)
        self._ids = seen
        self.rec.log("stats/latency_ms", rr.Scalars(float(message.get("latency_ms", 0.0))))
        if message.get("reason"):
            self.rec.log("log", rr.TextLog(f"frame {message.get('frame')}: {message['reason']}", level="WARN"))
        self.frames += 1

    def status(self, message: dict) -> None:
        """The worker's state, logged when it changes."""
        state = str(message.get("state", ""))
        if state and state != self._worker_state:
            self._worker_state = state
            self.rec.log("log", self.rr.TextLog(f"worker {state}", level="INFO"))

    def close(self) -> None:
        """Flush and close the recording (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.stream.close()


def open_view_sink(name: str, *, rrd: str = "", view: bool = False, url: str = "", port: int = 9876,
                   live: bool = False, depth_step: int = DEPTH_STEP) -> RerunSink | None:
    """The viewer sink of a run's ``--view`` / ``--rrd`` settings (None when neither is set);
    ``name``: the camera id; the rest as :func:`~swarmpose.publish.rerun_stream.open_stream`."""
    if not (view or rrd):
        return None
    stream = open_stream(name, rrd=rrd, view=view, url=url, port=port, live=live)
    try:
        return RerunSink(stream, depth_step)
    except Exception:
        stream.close()
        raise
