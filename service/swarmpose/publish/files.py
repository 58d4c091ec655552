"""Offline-replay files of a run: ``poses.jsonl``, ``poses.csv``, ``poses.bvh`` and ``overlay.mp4``.

Every writer is a :class:`~swarmpose.publish.sink.Sink` that flushes after every frame, so
a run that dies leaves files holding every frame written so far:

* :class:`JsonlSink` — each frame message (``protocol/frame.schema.json``) as one compact
  JSON line;
* :class:`CsvSink` — one row per frame and body (:data:`CSV_COLUMNS`): metres in the frame
  the message's ``coordinates`` names (the camera frame, OpenCV: x right, y down, z forward,
  or the floor-aligned world frame, y up; the ``coordinates`` column says which), pixels, the
  36-D pose; empty cells where a value is unknown;
* :class:`BvhSink` — one body id's animation of the tracking body's bone rig, centimetres,
  Y up, standing on the floor in the world frame wherever the message knows it
  (``camera_to_world``); :class:`PerIdBvhSink` keeps one per id: ``poses.bvh`` for id 0,
  ``poses_id<N>.bvh`` for id N, created when N first appears;
* :class:`~swarmpose.publish.overlay.OverlaySink` — every body's skeleton drawn over the video;
* :class:`~swarmpose.publish.ros_bag.RosBagSink` — ``poses_ros2/``, a ROS 2 bag (MCAP) of every
  joint as TF and the skeletons as markers.

:func:`open_recording` opens all of them in one folder. The BVH sinks live in
:mod:`swarmpose.publish.bvh_file` (imported here as before). A file that cannot be created or
written raises :class:`~swarmpose.core.errors.OutputError` naming it.
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path

from swarmpose.body.joint_set import EXTRA_JOINTS, SKELETON_NAMES
from swarmpose.body.skeleton import EVAL_JOINTS, POSE_DIM
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import OutputError
from swarmpose.messages import POSE_NAMES, encode
from swarmpose.publish.bvh_file import BodyOf, PerIdBvhSink
from swarmpose.publish.file_sink import FileSink, write_error
from swarmpose.publish.overlay import OverlaySink
from swarmpose.publish.ros_bag import BAG_NAME, RosBagSink, is_earlier_bag, remove_earlier_bag, rosbags_missing
from swarmpose.publish.sink import Sink
from swarmpose.sources.base import Frame

log = logging.getLogger(__name__)

FRAME_COLUMNS: tuple[str, ...] = ("frame", "capture_ns", "received_ns", "publish_ns", "latency_ms", "coordinates")
BODY_COLUMNS: tuple[str, ...] = ("body_id", "state", "reason")
JOINT_FIELDS: tuple[str, ...] = ("x", "y", "z", "u", "v", "confidence")
ORIENTATION_FIELDS: tuple[str, ...] = ("qx", "qy", "qz", "qw")
CSV_COLUMNS: tuple[str, ...] = (FRAME_COLUMNS + BODY_COLUMNS
                                + tuple(f"{j}_{f}" for j in EVAL_JOINTS for f in JOINT_FIELDS)
                                + POSE_NAMES + ("objective",)
                                + tuple(f"{j}_{f}" for j in EXTRA_JOINTS for f in JOINT_FIELDS)
                                + tuple(f"{j}_{f}" for j in SKELETON_NAMES for f in ORIENTATION_FIELDS))
"""Columns of poses.csv: frame fields (``coordinates``: ``camera`` or ``world``, the frame of the
row's metres, pose and orientations), body fields, per evaluation joint x y z (m), u v (px) and
confidence, the 36 pose entries, ``objective`` (E of the chosen pose); then (protocol 7, after the
columns earlier files had, so that they keep their places) x y z u v confidence of the joints the
full set adds (``EXTRA_JOINTS``) and qx qy qz qw, the orientation quaternion, of every joint of the
full set (``SKELETON_NAMES``)."""


class JsonlSink(FileSink):
    """``poses.jsonl``: every frame message as one compact UTF-8 JSON line, flushed at once."""

    what = "the JSON lines file"

    def __init__(self, path: str | Path) -> None:
        super().__init__(path, "wb")

    def frame(self, message: dict, frame: Frame | None = None) -> None:
        """Append ``message`` as one line."""
        self._check_open()
        line = encode(message) + b"\n"
        try:
            self._file.write(line)
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
        self._flush()
        self.frames += 1


def _cells(values, count: int) -> list:
    return [""] * count if values is None else ["" if v is None else v for v in values]


def csv_rows(message: dict) -> list[list]:
    """The poses.csv rows (each in :data:`CSV_COLUMNS` order) of one frame message: one per
    body, or one with empty body cells (and the frame's reason) when there is none."""
    head = [message.get(c, "camera" if c == "coordinates" else "") for c in FRAME_COLUMNS]
    bodies = message.get("bodies") or []
    if not bodies:
        return [head + ["", "", message.get("reason", "")] + [""] * (len(CSV_COLUMNS) - len(head) - 3)]
    rows = []
    for body in bodies:
        row = head + [body.get("id", ""), body.get("state", ""), body.get("reason") or message.get("reason", "")]
        joints = body.get("joints") or {}
        for name in EVAL_JOINTS:
            joint = joints.get(name) or {}
            row += _cells(joint.get("position_m"), 3) + _cells(joint.get("pixel"), 2)
            row.append(joint.get("confidence", ""))
        row += _cells(body.get("pose"), POSE_DIM)
        row.append((body.get("objective") or {}).get("E", ""))
        for name in EXTRA_JOINTS:
            joint = joints.get(name) or {}
            row += _cells(joint.get("position_m"), 3) + _cells(joint.get("pixel"), 2)
            row.append(joint.get("confidence", ""))
        for name in SKELETON_NAMES:
            row += _cells((joints.get(name) or {}).get("orientation_xyzw"), 4)
        rows.append(row)
    return rows


class CsvSink(FileSink):
    """``poses.csv``: a header of :data:`CSV_COLUMNS`, then :func:`csv_rows` of every frame."""

    what = "the CSV file"

    def __init__(self, path: str | Path) -> None:
        super().__init__(path, "w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)
        try:
            self._writer.writerow(CSV_COLUMNS)
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
        self._flush()

    def frame(self, message: dict, frame: Frame | None = None) -> None:
        """Append the rows of ``message``."""
        self._check_open()
        try:
            self._writer.writerows(csv_rows(message))
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
        self._flush()
        self.frames += 1


def open_recording(out_dir: str | Path, body: SkinnedBody, fps: float = 30.0, overlay: bool = True,
                   body_of: BodyOf | None = None, ros_bag: bool = True, ros_depth: bool = False) -> list[Sink]:
    """The replay sinks of folder ``out_dir`` (created if needed): poses.jsonl, poses.csv,
    the BVH files (:class:`PerIdBvhSink`: poses.bvh for id 0, poses_id<N>.bvh for id N,
    animating ``body`` at ``fps``, or with ``body_of`` each id's current body), with
    ``overlay`` overlay.mp4 and with ``ros_bag`` the ROS 2 bag ``poses_ros2/`` (with
    ``ros_depth`` holding the depth too; left out, with one warning, where the ``rosbags`` package
    is missing). An earlier run's ``poses_id<N>.bvh`` and ``poses_ros2/`` there are removed (the
    folder then holds one run's files); something else named ``poses_ros2`` in the way of the bag
    is an OutputError."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder {out}: {exc.strerror or exc}; "
                          "choose a writable output folder (or remove the file in its way)") from exc
    stale = sorted(out.glob("poses_id*.bvh"))  # an earlier run's people: this run writes its own, or none
    for path in stale:
        try:
            path.unlink()
        except OSError as exc:
            raise OutputError(f"cannot remove {path}, an earlier run's output: {exc.strerror or exc}; choose an "
                              "empty output folder") from exc
    bag = out / BAG_NAME
    if (ros_bag or is_earlier_bag(bag)) and remove_earlier_bag(bag):  # its poses are another run's
        stale.append(bag)
    if stale:
        log.info("%s: removed %s of an earlier run (its other files are written anew)", out,
                 ", ".join(p.name for p in stale))
    makers = [lambda: JsonlSink(out / "poses.jsonl"), lambda: CsvSink(out / "poses.csv"),
              lambda: PerIdBvhSink(out, body, fps, body_of)]
    if overlay:
        makers.append(lambda: OverlaySink(out / "overlay.mp4", fps))
    missing = rosbags_missing() if ros_bag else ""
    if missing:
        log.warning("%s not written: %s; install it with `pip install rosbags` (a dependency of swarmpose), or "
                    "leave the bag out with --no-ros-bag", bag, missing)
    elif ros_bag:
        makers.append(lambda: RosBagSink(bag, depth=ros_depth))
    sinks: list[Sink] = []
    try:
        for make in makers:
            sinks.append(make())
    except OutputError:
        for sink in sinks:
            sink.close()
        raise
    return sinks


__all__ = ["CSV_COLUMNS", "CsvSink", "JsonlSink", "csv_rows", "open_recording"]
