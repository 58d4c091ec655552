"""Synthetic RGBD sequences with ground truth, from bodies and motions (paper §3.1).

Output folder (Open3D's RGBD layout plus ground truth)::

    color/000000.png ...     RGB render of the people in a room (floor + back wall), each
                             in one colour, or with ``clothes`` dressed
                             (:mod:`swarmpose.sim.clothing`: skin, shirt, trousers, shoes)
    depth/000000.png ...     uint16 millimetres, 0 = no measurement, Kinect-like noise
    intrinsic.json           Open3D PinholeCameraIntrinsic JSON
    groundtruth.jsonl        one line per frame: frame, timestamp_ns, pose (36-D, camera
                             frame), joints3d (m) and joints2d (px) of the evaluation
                             joints, detections of the simulated 2D detector (person 1's);
                             with several people also ``people``, see below
    sequence.json            how it was made: body, shape, motion, camera, noise, seed
                             (and ``people``: body, shape, motion, x, z, yaw of each;
                             ``props``: each prop's kind, spec, place and size in the world
                             and its centre, axes and corners in the camera frame)

One person (:func:`synthesize`, or :func:`synthesize_people` with one person) writes no
``people`` in ``groundtruth.jsonl``: the file is the single-person format, byte for byte.
Several people (:func:`synthesize_people`, ids 1..P in the order given) are rendered in
one ray cast so they occlude each other, each in its own colour (dressed: its shirt's); each line keeps
person 1's top-level fields (old readers see person 1) and adds ``people``: per person
``id``, ``pose``, ``joints3d``, ``joints2d``, ``detections`` (keypoints hidden by another
person are missing), ``visible`` (share of the person's silhouette not hidden by others,
0..1), ``box`` ([x0, y0, x1, y1] px, inclusive, of its visible pixels, or null) and
``occluded`` (the evaluation joints hidden by another person or a prop).

Props (``SynthConfig.props``, :mod:`swarmpose.sim.props`: a stool, a table, a box) are rendered
with the room in their own colour; they hide joints from the simulated detector as another
person does, and a single-person file with props adds the top-level ``occluded``.

World frame while placing things: X = the subject's left at the first frame, Y = up,
Z = forward, floor at y = 0. The camera stands ``camera_distance`` in front of the
people's start positions' centre, turned ``camera_yaw`` about the vertical, its lens
``camera_height`` above the floor, looking at the middle of the bodies (see
:mod:`swarmpose.sim.scene`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from swarmpose.body.kinematics import transform_points
from swarmpose.body.skeleton import EVAL_JOINTS, LAYOUTS
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, OutputError
from swarmpose.core.progress import progress_bar
from swarmpose.detect.simulated import SimulatedNoise, person_size, simulate_detections
from swarmpose.motion.sequence import Motion
from swarmpose.sim.clothing import clothing_albedo, shirt_albedo
from swarmpose.sim.depth_noise import KinectNoise
from swarmpose.sim.props import PropSpec, place_props
from swarmpose.sim.render import Renderer, Room
from swarmpose.sim.scene import PersonSpec, SceneFilming, ScenePerson, check_scene, place_in_world, place_people

OCCLUSION_MARGIN = 0.05
"""A point counts as hidden by another person when that person's surface at the point's pixel
lies more than this (m) in front of it."""


@dataclass(frozen=True)
class SynthConfig:
    """How to film: frames, rate (Hz), camera (m, degrees), noise, detector, skinning, seed,
    whether the bodies wear clothes (:mod:`swarmpose.sim.clothing`) or one colour each, and the
    props in the room (:mod:`swarmpose.sim.props`)."""

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
    clothes: bool = False
    props: tuple[PropSpec, ...] = ()

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
    film = place_scene([ScenePerson(PersonSpec(), body, motion)], config)
    return Filming(film.poses[0], film.rotation, film.eye, film.room)


def place_scene(people: Sequence[ScenePerson], config: SynthConfig) -> SceneFilming:
    """Stand every person at its start on the floor, put the camera in front of them, express
    their poses in its frame."""
    placed = [place_in_world(p.body, p.motion, config.frames, p.spec.x, p.spec.z, p.spec.yaw_deg, config.skinning)
              for p in people]
    film = place_people(placed, config.camera_distance, config.camera_yaw_deg, config.camera_height)
    if not config.props:
        return film
    props = place_props(config.props, [p.body for p in placed], [p.poses for p in placed],
                        [p.rotations for p in placed], film.eye, config.skinning)
    room = replace(film.room, props=tuple(prop.solid(film.rotation, film.eye) for prop in props))
    return replace(film, room=room, props=props)


def occluded_points(points3d: np.ndarray, points2d: np.ndarray, depth: np.ndarray, labels: np.ndarray,
                    person: int, margin: float = OCCLUSION_MARGIN) -> np.ndarray:
    """(N,) bool: points hidden by *another* person or a prop.

    points3d (N, 3) camera frame m and points2d (N, 2) px of person ``person`` (1-based id);
    depth (H, W) m and labels (H, W) (0 = nobody, k = person k, -m = prop m) of the noise-free
    render. A point is hidden when its nearest pixel shows another person or a prop whose surface
    lies more than ``margin`` m in front of it; points outside the image or behind the camera are not (the
    detector drops those anyway), nor are points behind the person's own body.
    """
    h, w = labels.shape
    uv = np.round(np.nan_to_num(points2d, nan=-1.0, posinf=-1.0, neginf=-1.0)).astype(np.int64)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h) & (points3d[:, 2] > 0)
    out = np.zeros(len(points3d), dtype=bool)
    u, v = uv[inside, 0], uv[inside, 1]
    who = labels[v, u]
    out[inside] = (who != 0) & (who != person) & (depth[v, u] < points3d[inside, 2] - margin)
    return out


def visible_share(labels: np.ndarray, person: int, silhouette: np.ndarray) -> tuple[float, list[int] | None]:
    """(share of ``silhouette`` (H, W) bool, the person's pixels alone, that ``labels`` still
    gives to ``person``; [x0, y0, x1, y1] px, inclusive, of those visible pixels or None)."""
    own = labels == person
    total = int(np.count_nonzero(silhouette))
    seen = int(np.count_nonzero(own & silhouette))
    if seen == 0:
        return 0.0, None
    rows = np.flatnonzero(np.any(own, axis=1))
    cols = np.flatnonzero(np.any(own, axis=0))
    return seen / total, [int(cols[0]), int(rows[0]), int(cols[-1]), int(rows[-1])]


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
    return _render(out, [ScenePerson(PersonSpec(), body, motion)], config, description, progress, scene=False)


def synthesize_people(people: Sequence[ScenePerson], out: Path, config: SynthConfig = SynthConfig(),
                      description: dict | None = None, progress: bool = True) -> dict:
    """Render ``config.frames`` frames of several people (ids 1..P in this order) into ``out``.

    Each person's spec places it (start x, z and yaw); ``sequence.json`` lists them. Returns
    a summary: frames written, the people's depth range (m), per person its id, body, height
    (m), motion, start x, z (m), yaw (degrees) and mean visible share.
    """
    check_scene([p.spec for p in people])
    return _render(out, list(people), config, description, progress, scene=True)


def _render(out: Path, people: list[ScenePerson], config: SynthConfig, description: dict | None,
            progress: bool, scene: bool) -> dict:
    import cv2

    config.validate()
    for k, p in enumerate(people, 1):
        if len(p.motion) < config.frames:
            who = f"person {k}: " if len(people) > 1 else ""
            raise ConfigError(f"{who}motion {p.motion.name!r} has {len(p.motion)} frames at {p.motion.fps:g} fps; "
                              f"ask for --frames {len(p.motion)} or fewer")
    out = Path(out)
    _prepare_output(out)
    film = place_scene(people, config)
    intr = config.intrinsics
    renderer = Renderer(intr)
    layout = LAYOUTS[config.layout]
    intr.save(out / "intrinsic.json")
    first = people[0]
    meta = {
        "schema": "swarmpose.sequence", "version": 1, "frames": config.frames, "fps": config.fps,
        "seed": config.seed, "body": first.body.name, "motion": first.motion.name, "skinning": config.skinning,
        "clothes": config.clothes,
        "camera": {"distance_m": config.camera_distance, "yaw_deg": config.camera_yaw_deg,
                   "height_m": config.camera_height, "world_to_camera_rotation": film.rotation.tolist(),
                   "eye_world_m": film.eye.tolist()},
        "depth_noise": config.noise.as_dict(), "detector": {"layout": layout.name, **config.detector.as_dict()},
        **(description or {}),
    }
    if scene:
        meta["people"] = [{"id": k, **p.spec.as_dict(), "body_name": p.body.name, "motion_name": p.motion.name,
                           "height_m": round(p.body.height, 4)} for k, p in enumerate(people, 1)]
    if film.props:
        meta["props"] = [prop.as_dict(film.rotation, film.eye) for prop in film.props]
    (out / "sequence.json").write_text(json.dumps(meta, indent=2))

    albedos = ([clothing_albedo(p.body, shirt_albedo(k), k) for k, p in enumerate(people)] if config.clothes
               else None)  # None: each person in one colour
    several = len(people) > 1
    hiders = several or bool(film.props)  # anything that can hide a person's joints from the detector
    depth_range = [np.inf, -np.inf]
    visible_sum = np.zeros(len(people))
    with open(out / "groundtruth.jsonl", "w", encoding="utf-8") as gt, \
            progress_bar("synth", config.frames, enabled=progress) as bar:
        for i in range(config.frames):
            transforms = [p.body.transforms(film.poses[k][i:i + 1]) for k, p in enumerate(people)]
            meshes = [(p.body.skin(t, config.skinning)[0], p.body.triangles) for p, t in zip(people, transforms)]
            depth, colour, labels = renderer.render_people(meshes, film.room, albedos)
            noisy = config.noise.apply(depth, np.random.default_rng([config.seed, i, 1]))
            seen = noisy[(labels > 0) & (noisy > 0)]
            if seen.size:
                depth_range = [min(depth_range[0], float(seen.min())), max(depth_range[1], float(seen.max()))]
            name = f"{i:06d}.png"
            cv2.imwrite(str(out / "color" / name), cv2.cvtColor(colour, cv2.COLOR_RGB2BGR))
            cv2.imwrite(str(out / "depth" / name), np.round(noisy * 1000.0).astype(np.uint16))
            truths = []
            for k, (p, t) in enumerate(zip(people, transforms)):
                truth = _person_truth(p.body, film.poses[k][i], t, k, i, depth, labels, intr, layout, config, hiders)
                if several:
                    truth["visible"], truth["box"] = visible_share(labels, k + 1, renderer.silhouette(*meshes[k]))
                    visible_sum[k] += truth["visible"]
                    truth["visible"] = round(truth["visible"], 4)
                truths.append(truth)
            record = {"frame": i, "timestamp_ns": int(round(i * 1e9 / config.fps)),
                      **{key: truths[0][key] for key in ("pose", "joints3d", "joints2d", "detections")}}
            if several:
                record["people"] = [{"id": k, **truth} for k, truth in enumerate(truths, 1)]
            elif hiders:
                record["occluded"] = truths[0]["occluded"]
            gt.write(json.dumps(record, allow_nan=False) + "\n")
            gt.flush()
            bar.update(1)
    summary = {"out": str(out), "frames": config.frames, "body": first.body.name, "motion": first.motion.name,
               "person_depth_m": depth_range if np.isfinite(depth_range[0]) else None,
               "config": {k: v for k, v in asdict(config).items() if k in ("fps", "seed", "camera_distance",
                                                                             "camera_yaw_deg", "camera_height")}}
    if film.props:
        summary["props"] = meta["props"]
    if scene:
        summary["people"] = [{"id": k, "body": p.body.name, "height_m": p.body.height, "motion": p.motion.name,
                              "x": p.spec.x, "z": p.spec.z, "yaw": p.spec.yaw_deg,
                              "mean_visible": round(float(visible_sum[k - 1] / config.frames), 3) if several else 1.0}
                             for k, p in enumerate(people, 1)]
    return summary


def _person_truth(body: SkinnedBody, pose: np.ndarray, transforms: np.ndarray, index: int, frame: int,
                  depth: np.ndarray, labels: np.ndarray, intr: Intrinsics, layout, config: SynthConfig,
                  hiders: bool) -> dict:
    """One person's ground truth of one frame: pose, evaluation joints 3D / 2D, simulated
    detections (points hidden by another person or a prop missing) and, when the scene has
    several people or props (``hiders``), the evaluation joints so hidden."""
    by_name = {p: k for k, p in enumerate(body.point_names)}
    pts3 = transform_points(body.point_bones, body.point_rest, transforms)[0]
    pts2 = intr.project(pts3)
    hidden = occluded_points(pts3, pts2, depth, labels, index + 1) if hiders else np.zeros(len(pts3), bool)
    depth_ok = {p: bool(pts3[k, 2] > 0) and not hidden[k] for p, k in by_name.items()}
    det = simulate_detections(layout, {p: pts2[k] for p, k in by_name.items()}, depth_ok, person_size(pts2),
                              intr, config.detector, config.seed, frame, stream=index)
    truth = {
        "pose": pose.tolist(),
        "joints3d": {j: pts3[by_name[j]].round(6).tolist() for j in EVAL_JOINTS},
        "joints2d": {j: pts2[by_name[j]].round(3).tolist() for j in EVAL_JOINTS},
        "detections": {"layout": layout.name, "keypoints": det},
    }
    if hiders:
        truth["occluded"] = [j for j in EVAL_JOINTS if hidden[by_name[j]]]
    return truth
