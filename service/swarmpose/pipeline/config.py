"""What a run of swarmpose does: :class:`ServiceConfig`, with the tracker's settings nested.

One declaration (see :mod:`swarmpose.core.settings`) gives every command its flags, the
TOML file its keys and the environment its ``SWARMPOSE_*`` variables
(:mod:`swarmpose.cli.settings` loads them in layers). Leaf names are unique, so a setting
is spelt the same everywhere: ``particles`` is ``--particles``, ``SWARMPOSE_PARTICLES``
and ``particles = 64`` (top level or in a ``[tracker]`` table).
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import check_settings, section, setting
from swarmpose.tracking.config import TrackerConfig

ZENOH_MODES = ("peer", "client", "off")
SOURCE_FORMS = ("folder:DIR, rgbd:C.png,D.png,K.json, mkv:FILE, bag:FILE, openni2:[FILE.oni|URI], "
                "utdmhad:aA_sS_tT_depth.mat, realsense:[SERIAL], azure:[INDEX], or a bare folder / recording file")


@dataclass(frozen=True)
class ZenohConfig:
    """How results are published over zenoh."""

    zenoh_mode: str = setting("peer", "zenoh: peer, client (through a router) or off (no publishing)",
                              choices=ZENOH_MODES, everyday=True)
    connect: tuple[str, ...] = setting((), "zenoh endpoints to connect to, e.g. tcp/192.168.1.10:7447",
                                       everyday=True)
    listen: tuple[str, ...] = setting((), "zenoh endpoints to listen on, e.g. tcp/0.0.0.0:7447")
    multicast: bool = setting(True, "zenoh multicast scouting (automatic discovery of peers on the LAN)")
    zenoh_config: str = setting("", "a zenoh JSON5 configuration file, applied before the other zenoh settings")

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class ServiceConfig:
    """Everything ``track``, ``eval``, ``replay`` and ``serve`` run with (and the Python API's
    :class:`swarmpose.Tracker`, for the settings it shares)."""

    source: str = setting("", "frame source: a sequence folder, a recording (.mkv .bag .oni) or a URI such as "
                              "realsense:", everyday=True)
    """Every form: :data:`SOURCE_FORMS` (README, frame sources)."""
    detector: str = setting("auto", "2D joints: auto, movenet, blazepose, simulated, onnx:MODEL.onnx or "
                                    "openpose-json:DIR", aliases=("joints",), everyday=True)
    """auto: the simulated detector where the source recorded detections, else movenet;
    movenet and blazepose are loaded from the models folder; onnx:MODEL.onnx[?adapter=...],
    openpose-json:DIR[?layout=...]."""
    models: str = setting("", "folder of the .onnx networks, searched before ~/.local/share/swarmpose/models",
                          everyday=True)
    """Then ../shared/assets/pose2d."""
    body: str = setting("builtin", "body model: builtin, makehuman:DIR or a .glb/.gltf file", everyday=True)
    shape: str = setting("", "body shape: a preset (male, female, ...) or sliders (height=1.8,... or "
                             "gender=0.3,...)", everyday=True)
    """Builtin: height=1.8,torso=1.1,...; MakeHuman: gender=0.3,weight=0.8,... (sliders 0..1);
    empty: the body's default."""
    tracker: TrackerConfig = section(TrackerConfig, "the tracker")
    camera_id: str = setting("camera0", "the <camera> of the zenoh keys swarmpose/<camera>/... and of every message")
    frames: int = setting(0, "stop after this many frames (0 = all)", minimum=0, aliases=("max_frames",),
                          everyday=True)
    overlay: bool = setting(True, "write overlay.mp4 (the skeleton over the colour video) with the other files")
    ros_bag: bool = setting(True, "write poses_ros2/, a ROS 2 bag in MCAP (every joint on /tf, skeleton markers), "
                                  "with the other files")
    """docs/outputs.md, the ROS 2 bag: its topics, frame ids and how to play it."""
    ros_depth: bool = setting(False, "the ROS 2 bag also holds each frame's depth (sensor_msgs/Image 32FC1, m) and "
                                     "CameraInfo")
    coordinates: str = setting("camera", "joints and poses in camera (OpenCV axes) or world coordinates (y up, "
                                         "on the floor)", choices=("camera", "world"), everyday=True)
    """world: floor-aligned, y up, the floor at y = 0, the origin under the first tracked person;
    needs a floor. It applies to the messages, poses.jsonl and poses.csv."""
    floor: str = setting("auto", "the world frame's floor: auto (fitted to the depth), off or an extrinsics JSON "
                                 "file")
    """The file holds {camera_to_world}, {floor: {normal, offset_m}} or {camera_height_m, pitch_deg,
    roll_deg}. poses.bvh stands on the floor where it is known."""
    zenoh: ZenohConfig = section(ZenohConfig, "zenoh publishing")
    rate: float = setting(0.0, "deliver a recording at this many frames/s (0: as recorded for serve, else as "
                               "fast as possible)", minimum=0.0)
    """Live cameras set their own rate."""
    loop: bool = setting(False, "start a recording over when it ends (serve)")
    frame_budget_ms: float | None = setting(None, "serve: the time a frame's tracking may take, ms (auto: 0.9 "
                                                   "camera frame periods; 0: the full search)", kind="float?",
                                            minimum=0.0)
    """Each frame's search and polish are sized to it (shared by the people in view), so the poses
    keep up with the camera (:mod:`swarmpose.tracking.budget`, :func:`~swarmpose.tracking.budget.live_budget_ms`)."""
    record: str = setting("", "serve: also write poses.jsonl/csv/bvh and overlay.mp4 into this folder",
                          everyday=True)
    status_period_s: float = setting(1.0, "seconds between status messages", minimum=0.01)
    health_file: str = setting("", "also write each status message here (for `swarmpose health`)")
    reopen_s: float = setting(5.0, "seconds between attempts to reopen a failed live source or zenoh router",
                              minimum=0.0)
    view: bool = setting(False, "show the run in a rerun 3D viewer (without a display: served on --view-port)",
                         everyday=True)
    """Spawns a viewer where there is a display, else serves the view on --view-port for
    `rerun rerun+http://HOST:PORT/proxy` elsewhere."""
    view_url: str = setting("", "--view: stream to the rerun viewer already listening here, e.g. "
                                "rerun+http://laptop:9876/proxy")
    view_port: int = setting(9876, "--view: port of the spawned viewer, or of the view served without a display",
                             minimum=1, maximum=65535)
    rrd: str = setting("", "also write the rerun recording (depth, image, skeletons) to this .rrd file")
    """Open it with `rerun FILE.rrd`."""

    def __post_init__(self) -> None:
        from swarmpose.messages.schema import check_camera_id  # here: the messages package loads scipy

        check_camera_id(self.camera_id)
        check_settings(self)

    def require_source(self) -> ServiceConfig:
        """Self, or a ConfigError when no source is configured."""
        if not self.source:
            raise ConfigError(f"no source: pass --source URI ({SOURCE_FORMS}) or set SWARMPOSE_SOURCE")
        return self
