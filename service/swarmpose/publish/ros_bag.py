"""The ROS 2 bag of a run: ``poses_ros2/``, a rosbag2 folder with MCAP storage (``metadata.yaml``
and ``poses_ros2.mcap``), written with the ``rosbags`` package (no ROS installation needed).

:class:`RosBagSink` writes per frame message, stamped with the frame's capture time
(``capture_ns``: every header's ``stamp`` and the bag's log time):

* ``/tf`` (``tf2_msgs/msg/TFMessage``): per body with a pose, one transform per joint of the full
  set, parented along the skeleton (:mod:`swarmpose.publish.ros_skeleton`): the pelvis under the
  message's frame (the camera's id, e.g. ``camera0``, its optical frame: x right, y down, z
  forward; or ``world``), each other joint under its parent; child frames
  ``swarmpose/id<N>/<joint>``. Where the message knows ``camera_to_world``, also the camera's
  place: ``world`` -> camera in world coordinates, camera -> ``world`` in camera coordinates;
* ``/swarmpose/markers`` (``visualization_msgs/msg/MarkerArray``), one per frame: per body with a
  pose a ``LINE_LIST`` (id 0, the skeleton's links) and a ``SPHERE_LIST`` (id 1, the joints) in
  namespace ``id<N>``, in the body's id colour; when a body stops having a pose, ``DELETE`` of
  both;
* with ``depth``: ``/swarmpose/depth/image`` (``sensor_msgs/msg/Image``, ``32FC1``, metres, 0 =
  invalid) and ``/swarmpose/depth/camera_info`` (``sensor_msgs/msg/CameraInfo``, the pinhole
  without distortion), frame id the camera's.

Message definitions are ROS 2 Jazzy's; ``metadata.yaml`` is rosbag2's version 8 (ROS 2 Iron and
later). MCAP chunks of about 1 MiB go to disk as they fill and ``metadata.yaml`` is written by
:meth:`RosBagSink.close`, so a killed run leaves an incomplete bag (``ros2 bag reindex`` restores
the metadata). Failures raise :class:`~swarmpose.core.errors.OutputError` naming the bag.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from swarmpose.body.joint_set import SKELETON_NAMES, SKELETON_PARENTS
from swarmpose.body.kinematics import matrix_to_quaternion, to_xyzw
from swarmpose.core.errors import OutputError
from swarmpose.publish.file_sink import ClosingSink, write_error
from swarmpose.publish.overlay import id_color
from swarmpose.publish.ros_skeleton import body_joints, link_points, parent_relative
from swarmpose.sources.base import Frame

log = logging.getLogger(__name__)

BAG_NAME = "poses_ros2"
"""The bag's folder in the output folder (its MCAP file is ``poses_ros2.mcap``)."""
TF_TOPIC = "/tf"
MARKER_TOPIC = "/swarmpose/markers"
DEPTH_TOPIC = "/swarmpose/depth/image"
CAMERA_INFO_TOPIC = "/swarmpose/depth/camera_info"
JOINT_FRAME = "swarmpose/id{id}/{joint}"
"""A joint's TF frame id: stable per person (``id``) and joint name."""
MARKER_NS = "id{id}"
LINE_WIDTH_M = 0.02
SPHERE_DIAMETER_M = 0.05
BAG_FILES = ("metadata.yaml", f"{BAG_NAME}.mcap")
"""What a bag of this sink holds: an earlier run's may be removed (:func:`remove_earlier_bag`)."""


def joint_frame(body_id: int, joint: str) -> str:
    """The TF frame id of ``joint`` of person ``body_id``."""
    return JOINT_FRAME.format(id=int(body_id), joint=joint)


def message_frame(message: dict) -> str:
    """The frame id of a frame message's coordinates: ``world`` or the camera's id."""
    return "world" if message.get("coordinates") == "world" else str(message.get("camera") or "camera")


def rosbags_missing() -> str:
    """Why the ``rosbags`` package cannot be imported ("" when it can)."""
    try:
        import rosbags  # noqa: F401
    except ImportError as exc:
        return str(exc) or "rosbags cannot be imported"
    return ""


def is_earlier_bag(folder: Path) -> bool:
    """Whether ``folder`` is a bag this sink wrote: a folder of :data:`BAG_FILES` only."""
    return (folder.is_dir() and not folder.is_symlink()
            and all(p.name in BAG_FILES and p.is_file() for p in folder.iterdir()))


def remove_earlier_bag(folder: Path) -> bool:
    """Remove ``folder`` when it is an earlier run's bag (only :data:`BAG_FILES` in it); True
    when one was removed. Anything else there raises OutputError (nothing of the user's is
    deleted)."""
    if not folder.exists() and not folder.is_symlink():
        return False
    what = (f"{folder} is in the way of the ROS 2 bag and is not one this program wrote; move it away, choose "
            "another output folder or leave the bag out (--no-ros-bag)")
    if not is_earlier_bag(folder):
        raise OutputError(what)
    try:
        for path in list(folder.iterdir()):
            path.unlink()
        folder.rmdir()
    except OSError as exc:
        raise OutputError(f"cannot remove {folder}, an earlier run's ROS 2 bag: {exc.strerror or exc}; choose an "
                          "empty output folder") from exc
    return True


class RosBagSink(ClosingSink):
    """Writes the frame messages (and with ``depth`` each frame's depth) into the ROS 2 bag at
    ``folder`` (created; it must not exist: :func:`remove_earlier_bag`)."""

    what = "the ROS 2 bag"
    close_errors = (Exception,)  # rosbags' WriterError, OSError: finishing the MCAP file or metadata.yaml

    def __init__(self, folder: str | Path, depth: bool = False) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.path = Path(folder)
        self.paths = [self.path / name for name in reversed(BAG_FILES)]
        self.frames = 0
        self._closed = False
        self._with_ids: set[int] = set()  # the bodies the last marker array drew
        self._store = get_typestore(Stores.ROS2_JAZZY)
        self._types = self._store.types
        try:
            self._file = Writer(self.path, version=8, storage_plugin=StoragePlugin.MCAP)
            self._file.open()
            topics = {TF_TOPIC: "tf2_msgs/msg/TFMessage", MARKER_TOPIC: "visualization_msgs/msg/MarkerArray"}
            if depth:
                topics |= {DEPTH_TOPIC: "sensor_msgs/msg/Image", CAMERA_INFO_TOPIC: "sensor_msgs/msg/CameraInfo"}
            self._connections = {topic: self._file.add_connection(topic, kind, typestore=self._store)
                                 for topic, kind in topics.items()}
        except Exception as exc:  # rosbags' WriterError, OSError: either way the bag cannot be written
            raise write_error(self.what, self.path, exc) from exc

    # -- messages ----------------------------------------------------------------------------
    def _header(self, stamp_ns: int, frame_id: str):
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self._types["std_msgs/msg/Header"](
            stamp=self._types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id)

    def _transform(self, header, child: str, translation: np.ndarray, rotation: np.ndarray):
        t = self._types
        x, y, z = (float(v) for v in translation)
        qx, qy, qz, qw = (float(v) for v in rotation)
        return t["geometry_msgs/msg/TransformStamped"](
            header=header, child_frame_id=child,
            transform=t["geometry_msgs/msg/Transform"](
                translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                rotation=t["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)))

    def _camera_transform(self, message: dict, stamp: int) -> list:
        """The camera's place in the world, as one transform (none where it is unknown)."""
        matrix = message.get("camera_to_world")
        if matrix is None:
            return []
        m = np.asarray(matrix, dtype=np.float64)
        camera = str(message.get("camera") or "camera")
        if message.get("coordinates") != "world":  # the world under the camera: the inverse
            m = np.linalg.inv(m)
            parent, child = camera, "world"
        else:
            parent, child = "world", camera
        q = to_xyzw(matrix_to_quaternion(m[:3, :3]))
        return [self._transform(self._header(stamp, parent), child, m[:3, 3], q)]

    def _markers(self, header, body_id: int, positions: np.ndarray | None) -> list:
        """The body's two markers (a LINE_LIST of the links, a SPHERE_LIST of the joints at
        ``positions`` (K, 3) m), or with ``positions`` None, the DELETE of both."""
        marker = self._types["visualization_msgs/msg/Marker"]
        if positions is None:
            return [self._marker(header, body_id, marker_id, marker.DELETE, kind, 0.0, [])
                    for marker_id, kind in ((0, marker.LINE_LIST), (1, marker.SPHERE_LIST))]
        point = self._types["geometry_msgs/msg/Point"]
        return [self._marker(header, body_id, marker_id, marker.ADD, kind, size,
                             [point(x=float(x), y=float(y), z=float(z)) for x, y, z in points])
                for marker_id, kind, points, size in ((0, marker.LINE_LIST, link_points(positions), LINE_WIDTH_M),
                                                      (1, marker.SPHERE_LIST, positions, SPHERE_DIAMETER_M))]

    def _marker(self, header, body_id: int, marker_id: int, action: int, kind: int, size: float, points: list):
        """One marker of ``body_id`` in its id colour, its points in the header's frame."""
        t = self._types
        r, g, b = (c / 255.0 for c in id_color(body_id))
        identity = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                               orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                             w=1.0))
        return t["visualization_msgs/msg/Marker"](
            header=header, ns=MARKER_NS.format(id=body_id), id=marker_id, type=kind, action=action, pose=identity,
            scale=t["geometry_msgs/msg/Vector3"](x=size, y=size, z=size),
            color=t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=1.0),
            lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False, points=points,
            colors=[], texture_resource="",
            texture=t["sensor_msgs/msg/CompressedImage"](header=header, format="", data=np.zeros(0, np.uint8)),
            uv_coordinates=[], text="", mesh_resource="",
            mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
            mesh_use_embedded_materials=False)

    def _depth(self, frame: Frame, stamp: int, camera: str) -> None:
        t = self._types
        header = self._header(stamp, camera)
        depth = np.ascontiguousarray(frame.depth, dtype="<f4")
        height, width = depth.shape
        image = t["sensor_msgs/msg/Image"](header=header, height=height, width=width, encoding="32FC1",
                                           is_bigendian=0, step=4 * width, data=depth.view(np.uint8).reshape(-1))
        k = frame.intrinsics
        info = t["sensor_msgs/msg/CameraInfo"](
            header=header, height=height, width=width, distortion_model="plumb_bob", d=np.zeros(5),
            k=np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], dtype=np.float64), r=np.eye(3).reshape(-1),
            p=np.array([k.fx, 0, k.cx, 0, 0, k.fy, k.cy, 0, 0, 0, 1, 0], dtype=np.float64), binning_x=0,
            binning_y=0, roi=t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                   do_rectify=False))
        self._write(DEPTH_TOPIC, image, stamp)
        self._write(CAMERA_INFO_TOPIC, info, stamp)

    def _write(self, topic: str, msg, stamp: int) -> None:
        connection = self._connections[topic]
        self._file.write(connection, int(stamp), self._store.serialize_cdr(msg, connection.msgtype))

    # -- the sink ----------------------------------------------------------------------------
    def frame(self, message: dict, frame: Frame | None = None) -> None:
        """Write the frame's transforms and markers (and depth), stamped ``capture_ns``."""
        if self._closed:
            raise OutputError(f"{self.what} {self.path} is closed; open a new sink to write more frames")
        stamp = int(message.get("capture_ns") or 0)
        header = self._header(stamp, message_frame(message))
        transforms, markers, drawn = self._camera_transform(message, stamp), [], set()
        for body in message.get("bodies") or []:
            joints = body_joints(body)
            if joints is None:
                continue
            body_id = int(body["id"])
            translations, rotations = parent_relative(*joints)
            for name, parent, tr, rot in zip(SKELETON_NAMES, SKELETON_PARENTS, translations, rotations):
                parent_header = header if parent < 0 else self._header(stamp, joint_frame(body_id,
                                                                                          SKELETON_NAMES[parent]))
                transforms.append(self._transform(parent_header, joint_frame(body_id, name), tr, rot))
            markers += self._markers(header, body_id, joints[0])
            drawn.add(body_id)
        for gone in sorted(self._with_ids - drawn):
            markers += self._markers(header, gone, None)
        self._with_ids = drawn
        try:
            if transforms:
                self._write(TF_TOPIC, self._types["tf2_msgs/msg/TFMessage"](transforms=transforms), stamp)
            self._write(MARKER_TOPIC, self._types["visualization_msgs/msg/MarkerArray"](markers=markers), stamp)
            if frame is not None and DEPTH_TOPIC in self._connections:
                self._depth(frame, stamp, str(message.get("camera") or "camera"))
        except Exception as exc:  # rosbags' WriterError, OSError
            raise write_error(self.what, self.path, exc) from exc
        self.frames += 1


__all__ = ["BAG_NAME", "MARKER_TOPIC", "TF_TOPIC", "RosBagSink", "is_earlier_bag", "joint_frame", "message_frame",
           "remove_earlier_bag", "rosbags_missing"]
