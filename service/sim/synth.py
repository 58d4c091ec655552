"""Synthetic RGBD sequences with ground truth, from a body and a motion (paper §3.1).

Output folder (Open3D's RGBD layout plus ground truth)::

    color/000000.png ...     RGB render of the body in a room (floor + back wall)
    depth/000000.png ...     uint16 millimetres, 0 = no measurement, Kinect-like noise
    intrinsic.json           Open3D PinholeCameraIntrinsic JSON
    groundtruth.jsonl        one line per frame: frame, timestamp_ns, pose (36-D, camera
                             frame), joints3d (m) and joints2d (px) of the evaluation
                             joints, detections of the simulated 2D detector
    sequence.json            how it was made: body, shape, motion, camera, noise, seed

World frame while placing things: X = the subject's left at the first frame, Y = up,
Z = forward, floor at y = 0. The camera stands ``camera_distance`` in front of the
subject's start position, turned ``camera_yaw`` about the vertical, its lens
``camera_height`` above the floor, looking at the middle of the body.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from swarmpose.body.kinematics import matrix_to_quaternion, transform_points
from swarmpose.body.skeleton import EVAL_JOINTS, LAYOUTS, POSE_DIM
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics, look_at
from swarmpose.core.errors import ConfigError, OutputError
from swarmpose.core.progress import progress_bar
from swarmpose.detect.simulated import SimulatedNoise, person_size, simulate_detections
from swarmpose.motion.sequence import Motion
from swarmpose.sim.depth_noise import KinectNoise
from swarmpose.sim.render import Renderer, Room

WALL_BEHIND_SUBJECT = 2.0


@dataclass(frozen=True)
class SynthConfig:
    """How to film: frames, rate (Hz), camera (m, degrees), noise, detector, skinning, seed."""

    frames: int = 60
    fps: float = 30.0
    seed: int = 0
    camera_distance: float = 3.0
    camera_yaw_deg: float = 0.0
    camera_height: float = 1.2
    intrinsics: Intrinsics = field(default_factory=Intrinsics.kinect_v1)
    noise: KinectNoise = field(default_factory=KinectNoise)
    detector: SimulatedNoise = field(default_factory=SimulatedNoise)
    layout: str = "coco17"
    skinning: str = "dqs"

    def validate(self) -> None:
        """Raise ConfigError for values no camera or sequence can have."""
        if self.frames < 1:
            raise ConfigError(f"--frames must be at least 1, got {self.frames}")
        if not 0 < self.fps <= 1000:
            raise ConfigError(f"--fps must be within 0..1000, got {self.fps}")
        if self.seed < 0:
            raise ConfigError(f"--seed must be a non-negative integer, got {self.seed}")
        if not 0.5 <= self.camera_distance <= 8.0:
            raise ConfigError(f"--camera-distance must be within 0.5..8 m, got {self.camera_distance}")
        if not 0.1 <= self.camera_height <= 3.0:
            raise ConfigError(f"--camera-height must be within 0.1..3 m, got {self.camera_height}")
        if not np.isfinite(self.camera_yaw_deg):
            raise ConfigError(f"--camera-yaw must be a finite number of degrees, got {self.camera_yaw_deg}")
        if self.layout not in LAYOUTS:
            raise ConfigError(f"unknown keypoint layout {self.layout!r}; choose one of {sorted(LAYOUTS)}")


@dataclass(frozen=True)
class Filming:
    """Camera-frame poses (N, 36), the world -> camera rotation (3, 3) and eye (3,), the room."""

    poses: np.ndarray
    rotation: np.ndarray
    eye: np.ndarray
    room: Room


def place_camera(body: SkinnedBody, motion: Motion, config: SynthConfig) -> Filming:
    """Stand the body on the floor, put the camera in front of it, express poses in its frame."""
    n = min(len(motion), config.frames)
    root = np.array([0.0, body.floor_offset, 0.0]) + motion.root_offset[:n]
    rot = motion.root_rotation[:n]
    world = np.zeros((n, POSE_DIM))
    world[:, 0:3] = root
    world[:, 3:7] = matrix_to_quaternion(rot)
    world[:, 7:] = motion.angles[:n]
    lowest = min(float(body.pose(world[i:i + 64], config.skinning)[..., 1].min()) for i in range(0, n, 64))
    world[:, 1] -= lowest  # the lowest sole of the whole sequence touches the floor

    start = world[0, 0:3]
    yaw = np.radians(config.camera_yaw_deg)
    eye = np.array([start[0] + config.camera_distance * np.sin(yaw), config.camera_height,
                    start[2] + config.camera_distance * np.cos(yaw)])
    target = np.array([start[0], 0.5 * body.height, start[2]])
    r_cw = look_at(eye, target)
    cam = world.copy()
    cam[:, 0:3] = (world[:, 0:3] - eye) @ r_cw.T
    cam[:, 3:7] = matrix_to_quaternion(r_cw @ rot)
    ahead = target - eye
    ahead[1] = 0.0
    ahead /= np.linalg.norm(ahead)
    wall = eye + ahead * (config.camera_distance + WALL_BEHIND_SUBJECT)
    room = Room(floor_point=r_cw @ (np.zeros(3) - eye), floor_normal=r_cw @ np.array([0.0, 1.0, 0.0]),
                wall_point=r_cw @ (wall - eye), wall_normal=r_cw @ -ahead)
    return Filming(cam, r_cw, eye, room)


def _prepare_output(out: Path) -> None:
    try:
        (out / "color").mkdir(parents=True, exist_ok=True)
        (out / "depth").mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise OutputError(f"cannot write to output folder {out}: {exc.strerror or exc}; "
                          "choose a writable --out") from exc


def synthesize(body: SkinnedBody, motion: Motion, out: Path, config: SynthConfig = SynthConfig(),
               description: dict | None = None, progress: bool = True) -> dict:
    """Render ``config.frames`` frames of ``motion`` on ``body`` into folder ``out``.

    Returns a summary: frames written, the person's depth range (m) and paths.
    """
    import cv2

    config.validate()
    if len(motion) < config.frames:
        raise ConfigError(f"motion {motion.name!r} has {len(motion)} frames at {motion.fps:g} fps; "
                          f"ask for --frames {len(motion)} or fewer")
    out = Path(out)
    _prepare_output(out)
    film = place_camera(body, motion, config)
    intr = config.intrinsics
    renderer = Renderer(intr)
    layout = LAYOUTS[config.layout]
    intr.save(out / "intrinsic.json")
    meta = {
        "schema": "swarmpose.sequence", "version": 1, "frames": config.frames, "fps": config.fps,
        "seed": config.seed, "body": body.name, "motion": motion.name, "skinning": config.skinning,
        "camera": {"distance_m": config.camera_distance, "yaw_deg": config.camera_yaw_deg,
                   "height_m": config.camera_height, "world_to_camera_rotation": film.rotation.tolist(),
                   "eye_world_m": film.eye.tolist()},
        "depth_noise": config.noise.as_dict(), "detector": {"layout": layout.name, **config.detector.as_dict()},
        **(description or {}),
    }
    (out / "sequence.json").write_text(json.dumps(meta, indent=2))

    by_name = {p: k for k, p in enumerate(body.point_names)}
    person_depth = [np.inf, -np.inf]
    with open(out / "groundtruth.jsonl", "w", encoding="utf-8") as gt, \
            progress_bar("synth", config.frames, enabled=progress) as bar:
        for i in range(config.frames):
            h = film.poses[i:i + 1]
            transforms = body.transforms(h)
            verts = body.skin(transforms, config.skinning)[0]
            depth, colour, mask = renderer.render(verts, body.triangles, film.room)
            noisy = config.noise.apply(depth, np.random.default_rng([config.seed, i, 1]))
            seen = noisy[mask & (noisy > 0)]
            if seen.size:
                person_depth = [min(person_depth[0], float(seen.min())), max(person_depth[1], float(seen.max()))]
            name = f"{i:06d}.png"
            cv2.imwrite(str(out / "color" / name), cv2.cvtColor(colour, cv2.COLOR_RGB2BGR))
            cv2.imwrite(str(out / "depth" / name), np.round(noisy * 1000.0).astype(np.uint16))
            pts3 = transform_points(body.point_bones, body.point_rest, transforms)[0]
            pts2 = intr.project(pts3)
            det = simulate_detections(
                layout, {p: pts2[k] for p, k in by_name.items()}, {p: bool(pts3[k, 2] > 0) for p, k in by_name.items()},
                person_size(pts2), intr, config.detector, config.seed, i)
            record = {
                "frame": i, "timestamp_ns": int(round(i * 1e9 / config.fps)), "pose": h[0].tolist(),
                "joints3d": {j: pts3[by_name[j]].round(6).tolist() for j in EVAL_JOINTS},
                "joints2d": {j: pts2[by_name[j]].round(3).tolist() for j in EVAL_JOINTS},
                "detections": {"layout": layout.name, "keypoints": det},
            }
            gt.write(json.dumps(record, allow_nan=False) + "\n")
            gt.flush()
            bar.update(1)
    return {"out": str(out), "frames": config.frames, "body": body.name, "motion": motion.name,
            "person_depth_m": person_depth if np.isfinite(person_depth[0]) else None,
            "config": {k: v for k, v in asdict(config).items() if k in ("fps", "seed", "camera_distance",
                                                                          "camera_yaw_deg", "camera_height")}}
