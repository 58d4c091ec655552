"""People from depth: the floor plane and one mask per person (swarmpose.detect.floor / .people).

Oracles: the synthetic room and body rendered by Open3D ray casting without the room (the
person's true silhouette, head top and floor plane), analytic planes with the project's
Kinect noise, hand-labelled pixels of the real Kinect frames (heads, torsos, hands), and the
number of people seen in each real frame.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import ASSETS, needs_assets

from swarmpose.core.camera import Intrinsics, look_at
from swarmpose.core.errors import ConfigError, ShapeError, SwarmposeError
from swarmpose.detect.floor import FloorPlane, fit_floor
from swarmpose.detect.people import Segmentation, segment_people
from swarmpose.sim.depth_noise import KinectNoise

KINECT = Intrinsics.kinect_v1()
FIVE = ASSETS / "rgbd" / "kinect_five_people"
SKELTRACK = ASSETS / "rgbd" / "skeltrack_frames"
TWO_PEOPLE_FRAMES = {"1399145206", "82823944"}
"""The Skeltrack frames that hold two people (looked at): the others hold one."""


# ----------------------------------------------------------------------------- helpers
def check_invariants(seg: Segmentation, shape: tuple[int, int]) -> None:
    """What every segmentation promises: labels and masks agree, masks are disjoint, boxes
    are the masks' inclusive-exclusive boxes, people run left to right."""
    assert seg.labels.shape == shape and seg.labels.dtype == np.int32
    assert int(seg.labels.max(initial=0)) == len(seg.people)
    centres = []
    for k, person in enumerate(seg.people, start=1):
        assert person.mask.shape == shape and person.mask.dtype == bool
        assert np.array_equal(seg.labels == k, person.mask)
        rows, cols = np.flatnonzero(person.mask.any(1)), np.flatnonzero(person.mask.any(0))
        assert person.box.tolist() == [cols[0], rows[0], cols[-1] + 1, rows[-1] + 1]
        assert person.pixels == int(person.mask.sum())
        centres.append(0.5 * (person.box[0] + person.box[2]))
    assert centres == sorted(centres)
    json.dumps(seg.as_dict())  # JSON-friendly


def labels_at(seg: Segmentation, points: dict[str, tuple[int, int]]) -> dict[str, int]:
    """The label of the 7x7 window around each (x, y) pixel, which must be one label."""
    out = {}
    for name, (x, y) in points.items():
        window = np.unique(seg.labels[y - 3:y + 4, x - 3:x + 4])
        assert len(window) == 1, f"{name} at {(x, y)} straddles labels {window}"
        out[name] = int(window[0])
    return out


def plane_depth(normal, offset: float, seed: int = 0) -> np.ndarray:
    """Kinect-noisy depth (H, W) m of the plane normal @ p + offset = 0 seen by KINECT."""
    normal = np.asarray(normal, dtype=np.float64)
    normal = normal / np.linalg.norm(normal)
    x = (np.arange(KINECT.width) - KINECT.cx) / KINECT.fx
    y = (np.arange(KINECT.height) - KINECT.cy) / KINECT.fy
    along_ray = normal[0] * x[None, :] + normal[1] * y[:, None] + normal[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(along_ray < -1e-6, -offset / along_ray, 0.0)
    return KinectNoise().apply(z, np.random.default_rng(seed))


def camera_up(pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """The world's up direction in the frame of a camera pitched down and rolled (degrees)."""
    t, r = np.radians(pitch_deg), np.radians(roll_deg)
    up = np.array([0.0, -np.cos(t), -np.sin(t)])
    roll = np.array([[np.cos(r), -np.sin(r), 0.0], [np.sin(r), np.cos(r), 0.0], [0.0, 0.0, 1.0]])
    return roll @ up


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


# ------------------------------------------------------------------ synthetic sequences
@dataclass(frozen=True)
class SynthFrame:
    """One synthetic frame and its oracle: the body's true silhouette (rendered without the
    room), its true head top above the floor (m), and the true floor plane."""

    name: str
    depth: np.ndarray
    intrinsics: Intrinsics
    silhouette: np.ndarray
    top_m: float
    floor_normal: np.ndarray
    floor_offset: float


VIEWS = {  # name: (yaw deg, camera height m, distance m)
    "front": (0.0, 1.2, 3.0),
    "side_high": (90.0, 2.2, 4.0),
    "back_near": (180.0, 1.5, 2.0),  # the wall shows between the arms and the body
    "oblique_far_low": (-45.0, 0.8, 6.0),
}


@pytest.fixture(scope="session")
def walk_frames(tmp_path_factory) -> list[SynthFrame]:
    """Two frames of the built-in body walking, filmed from each of VIEWS, with oracles."""
    from swarmpose.body.loader import load_body
    from swarmpose.cli.main import main
    from swarmpose.sim.render import Renderer

    body = load_body("builtin")
    frames = []
    for name, (yaw, height, distance) in VIEWS.items():
        out = tmp_path_factory.mktemp(f"walk_{name}")
        assert main(["synth", "--body", "builtin", "--motion", "builtin:walk", "--frames", "2", "--out", str(out),
                     "--camera-yaw", str(yaw), "--camera-height", str(height),
                     "--camera-distance", str(distance), "--quiet"]) == 0
        sequence = json.loads((out / "sequence.json").read_text())
        rotation = np.array(sequence["camera"]["world_to_camera_rotation"])
        eye = np.array(sequence["camera"]["eye_world_m"])
        normal = rotation @ np.array([0.0, 1.0, 0.0])  # world up (floor at y = 0) in the camera frame
        offset = float(normal @ (rotation @ eye))       # normal @ p + offset = 0 on the floor
        intrinsics = Intrinsics.load(out / "intrinsic.json")
        renderer = Renderer(intrinsics)
        for line in (out / "groundtruth.jsonl").read_text().splitlines():
            truth = json.loads(line)
            vertices = body.pose(np.array([truth["pose"]]), sequence["skinning"])[0]
            _, _, silhouette = renderer.render(vertices, body.triangles)  # the body alone
            depth = cv2.imread(str(out / "depth" / f"{truth['frame']:06d}.png"), cv2.IMREAD_UNCHANGED) / 1000.0
            frames.append(SynthFrame(f"{name}/{truth['frame']}", depth, intrinsics, silhouette,
                                     float((vertices @ normal + offset).max()), normal, offset))
    return frames


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


@pytest.mark.slow
def test_synthetic_views_give_one_person_with_the_true_silhouette_and_height(walk_frames):
    for frame in walk_frames:
        seg = segment_people(frame.depth, frame.intrinsics)
        check_invariants(seg, frame.depth.shape)
        assert len(seg.people) == 1, f"{frame.name}: {len(seg.people)} people, rejected {seg.rejected}"
        person = seg.people[0]
        assert iou(person.mask, frame.silhouette) >= 0.8, frame.name
        inside = cv2.erode(frame.silhouette.view(np.uint8), np.ones((5, 5), np.uint8)).view(bool)
        holes = inside & (frame.depth <= 0)  # pixels of the body that lost their depth
        assert holes.sum() > 20 and person.mask[holes].mean() >= 0.9, frame.name
        assert abs(person.top_m - frame.top_m) <= 0.05, f"{frame.name}: top {person.top_m:.3f} vs {frame.top_m:.3f}"
        assert person.bottom_m < 0.15, frame.name  # feet near the floor
        rows, cols = np.nonzero(frame.silhouette)
        cut = rows.min() < 2 or cols.min() < 2 or rows.max() > frame.depth.shape[0] - 3 or \
            cols.max() > frame.depth.shape[1] - 3
        assert person.touches_border == cut, frame.name
        seen = frame.silhouette & (frame.depth > 0)  # the true centre of the visible body
        truth_centre = np.median(frame.intrinsics.point_map(frame.depth)[seen], axis=0)
        assert np.linalg.norm(person.centroid_m - truth_centre) < 0.1, frame.name


def test_wall_seen_between_arm_and_body_is_not_a_person(walk_frames):
    frame = next(f for f in walk_frames if f.name.startswith("back_near"))
    seg = segment_people(frame.depth, frame.intrinsics)
    assert len(seg.people) == 1
    assert seg.rejected.get("in_gap", 0) >= 1  # those wall patches were candidates, turned down
    wall_behind = ~frame.silhouette & (frame.depth > 0)
    assert (seg.labels.astype(bool) & wall_behind).sum() <= 0.02 * frame.silhouette.sum()


def test_floor_of_synthetic_room(walk_frames):
    for frame in walk_frames:
        floor = fit_floor(frame.depth, frame.intrinsics)
        assert floor is not None, frame.name
        assert angle_deg(floor.normal, frame.floor_normal) < 1.0, frame.name
        assert abs(floor.offset - frame.floor_offset) < 0.02, frame.name
        assert np.isclose(np.linalg.norm(floor.normal), 1.0)


def test_person_cut_by_the_image_border_is_found(walk_frames):
    frame = next(f for f in walk_frames if f.name.startswith("front"))
    # Slide the image left (a level camera turned: floor and wall stay planes) until the
    # person's left half leaves it; as many blank columns appear on the right.
    shift = int(np.median(np.nonzero(frame.silhouette)[1]))
    depth = np.zeros_like(frame.depth)
    depth[:, :-shift] = frame.depth[:, shift:]
    silhouette = np.zeros_like(frame.silhouette)
    silhouette[:, :-shift] = frame.silhouette[:, shift:]
    assert silhouette[:, 0].any() and silhouette.sum() < 0.7 * frame.silhouette.sum()
    seg = segment_people(depth, frame.intrinsics)
    assert len(seg.people) == 1
    person = seg.people[0]
    assert person.touches_border and person.box[0] == 0
    assert iou(person.mask, silhouette) >= 0.8


# ------------------------------------------------------------------ analytic scenes
@pytest.mark.parametrize("pitch, roll", [(0, 0), (20, 0), (40, 5), (45, -8)])
def test_floor_only_gives_the_floor_and_nobody(pitch, roll):
    up = camera_up(pitch, roll)
    depth = plane_depth(up, 1.3)  # the floor 1.3 m below the lens: up @ p + 1.3 = 0
    floor = fit_floor(depth, KINECT)
    assert floor is not None
    assert angle_deg(floor.normal, up) < 0.5
    assert abs(floor.offset - 1.3) < 0.01
    assert abs(floor.tilt_deg - angle_deg(up, np.array([0.0, -1.0, 0.0]))) < 0.5
    heights = floor.height(KINECT.point_map(depth)[depth > 0])
    assert np.median(np.abs(heights)) < 0.02
    seg = segment_people(depth, KINECT, floor=floor)
    assert seg.people == () and not seg.labels.any()


@pytest.mark.parametrize("normal, offset", [((0, 0, -1), 2.5), ((0.3, 0, -1), 3.0), ((0, 0.2, -1), 1.0),
                                            ((0, 0, -1), 0.9)])
def test_flat_wall_filling_the_frame_is_nobody(normal, offset):
    depth = plane_depth(normal, offset)
    assert (depth > 0).mean() > 0.95
    seg = segment_people(depth, KINECT)
    assert seg.floor is None
    assert seg.people == (), seg.rejected
    assert sum(seg.rejected.values()) >= 1


def test_furniture_is_nobody():
    """A chair-sized and a table-sized box standing on the floor before a wall (ray cast)."""
    import open3d as o3d

    from swarmpose.sim.render import Renderer, Room

    eye = np.array([0.0, 1.2, 3.0])
    rotation = look_at(eye, np.array([0.0, 0.6, 0.0]))
    verts, tris = [], []
    for size, corner in (((0.45, 0.85, 0.45), (-0.9, 0.0, -0.2)), ((1.2, 0.75, 0.8), (0.2, 0.0, -0.4))):
        box = o3d.geometry.TriangleMesh.create_box(*size).translate(corner)
        tris.append(np.asarray(box.triangles) + sum(len(v) for v in verts))
        verts.append((np.asarray(box.vertices) - eye) @ rotation.T)
    room = Room(floor_point=rotation @ -eye, floor_normal=rotation @ np.array([0.0, 1.0, 0.0]),
                wall_point=rotation @ (np.array([0.0, 0.0, -1.5]) - eye), wall_normal=rotation @ np.array([0.0, 0, 1]))
    depth, _, boxes = Renderer(KINECT).render(np.concatenate(verts), np.concatenate(tris), room)
    depth = KinectNoise().apply(depth, np.random.default_rng(1))
    assert boxes.mean() > 0.05
    seg = segment_people(depth, KINECT)
    assert seg.floor is not None and abs(seg.floor.offset - 1.2) < 0.02
    assert seg.people == (), [p.as_dict() for p in seg.people]


@pytest.mark.parametrize("fill", [0.0, np.nan, np.inf, -1.0])
def test_empty_depth_gives_nobody(fill):
    seg = segment_people(np.full((KINECT.height, KINECT.width), fill), KINECT)
    assert seg.people == () and seg.floor is None and not seg.labels.any() and seg.rejected == {}
    assert fit_floor(np.full((KINECT.height, KINECT.width), fill), KINECT) is None


# ------------------------------------------------------------------ bad arguments
def test_bad_shapes_and_arguments_raise_clear_errors():
    good = np.ones((KINECT.height, KINECT.width), np.float32)
    for bad in (np.ones((240, 320)), np.ones((KINECT.height, KINECT.width, 1)), np.ones(10), np.float32(1.0)):
        with pytest.raises(ShapeError, match="depth_m has shape"):
            segment_people(bad, KINECT)
        with pytest.raises(ShapeError, match="expected \\(480, 640\\)"):
            fit_floor(bad, KINECT)
    with pytest.raises(ShapeError, match="divide millimetres by 1000"):
        segment_people(good.astype(np.uint16), KINECT)
    with pytest.raises(ConfigError, match="floor must be"):
        segment_people(good, KINECT, floor="yes")
    with pytest.raises(ConfigError, match="floor must be"):
        segment_people(good, KINECT, floor=1.2)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ConfigError, match="max_people"):
            segment_people(good, KINECT, max_people=bad)
    with pytest.raises(ConfigError, match="unknown tuning option.*min_widht_m"):
        segment_people(good, KINECT, min_widht_m=0.1)
    with pytest.raises(ConfigError, match="unknown tuning option"):
        fit_floor(good, KINECT, iterations=5)
    with pytest.raises(ConfigError, match="stride"):
        segment_people(good, KINECT, stride=0)
    plane = FloorPlane(np.array([0.0, -1.0, 0.0]), 1.0, 100)
    with pytest.raises(ShapeError, match="points has shape"):
        plane.height(np.ones((4, 2)))
    assert issubclass(ShapeError, SwarmposeError) and issubclass(ConfigError, SwarmposeError)


def test_floor_plane_height_is_signed_distance():
    plane = FloorPlane(np.array([0.0, -1.0, 0.0]), 1.25, 10)
    pts = np.array([[0.3, 1.25, 2.0], [0.0, 0.0, 3.0], [1.0, 1.5, 1.0]])  # on the floor, lens level, below
    assert np.allclose(plane.height(pts), [0.0, 1.25, -0.25])
    assert plane.as_dict()["offset_m"] == 1.25 and json.dumps(plane.as_dict())


# ------------------------------------------------------------------ real Kinect frames
def five_people_depth() -> np.ndarray:
    return cv2.imread(str(FIVE / "five_people_depth_mm.png"), cv2.IMREAD_UNCHANGED) / 1000.0


FIVE_HEADS = {"green shirt": (82, 85), "blue top": (180, 125), "white shirt": (345, 130),
              "grey shirt": (418, 128), "dark shirt": (548, 82)}
FIVE_BACKS = {"green shirt": (80, 175), "blue top": (195, 190), "white shirt": (325, 200),
              "grey shirt": (425, 200), "dark shirt": (540, 200)}
"""Hand-labelled pixels of each person's head and back in the registered colour image."""


@needs_assets
def test_five_people_each_a_segment_of_plausible_height():
    calibration = json.loads((FIVE / "five_people_intrinsics.json").read_text())
    intrinsics = Intrinsics(**{k: calibration[k] for k in ("width", "height", "fx", "fy", "cx", "cy")})
    depth = five_people_depth()
    seg = segment_people(depth, intrinsics)
    check_invariants(seg, depth.shape)
    assert len(seg.people) == 5, seg.as_dict()
    heads, backs = labels_at(seg, FIVE_HEADS), labels_at(seg, FIVE_BACKS)
    assert sorted(heads.values()) == [1, 2, 3, 4, 5]  # left pair and middle pair come apart
    assert heads == backs
    for person in seg.people:
        assert 1.5 <= person.top_m <= 1.95
        assert 0.25 <= person.width_m <= 0.7
        assert 1.7 <= person.centroid_m[2] <= 3.0
    middle = [seg.people[heads[n] - 1] for n in ("white shirt", "grey shirt")]
    for person in middle:  # seen down to the feet
        assert not person.touches_border and person.bottom_m < 0.15
    # The floor: a patch of corridor floor between the feet lies on it.
    assert seg.floor is not None and seg.floor.tilt_deg < 15
    patch = intrinsics.point_map(depth)[440:475, 250:285].reshape(-1, 3)
    assert np.nanmedian(np.abs(seg.floor.height(patch))) < 0.03


@needs_assets
def test_five_people_max_people_keeps_the_largest():
    depth = five_people_depth()
    every = segment_people(depth, KINECT)
    three = segment_people(depth, KINECT, max_people=3, floor=every.floor)
    check_invariants(three, depth.shape)
    assert len(three.people) == 3 and three.rejected["beyond_max_people"] == 2
    largest = sorted(every.people, key=lambda p: -p.area_m2)[:3]
    assert sorted(p.box.tolist() for p in three.people) == sorted(p.box.tolist() for p in largest)


def skeltrack_frames() -> list[Path]:
    return sorted(SKELTRACK.glob("depth-data-*")) if SKELTRACK.is_dir() else []


def skeltrack_depth(name: str) -> np.ndarray:
    raw = np.fromfile(SKELTRACK / f"depth-data-{name}", dtype="<u2")
    return raw.reshape(480, 640) / 1000.0


@needs_assets
def test_skeltrack_frames_one_or_two_people():
    names = [p.name.split("-")[-1] for p in skeltrack_frames()]
    assert len(names) == 12 and TWO_PEOPLE_FRAMES <= set(names)
    for name in names:
        depth = skeltrack_depth(name)
        seg = segment_people(depth, KINECT)
        check_invariants(seg, depth.shape)
        assert seg.floor is None, name  # upper bodies, no floor in view
        assert len(seg.people) == (2 if name in TWO_PEOPLE_FRAMES else 1), f"{name}: {seg.as_dict()}"
        for person in seg.people:
            assert person.top_m is None and person.touches_border  # cut by the image bottom
            assert 0.8 <= person.centroid_m[2] <= 2.0


SKELTRACK_POINTS = {  # hand-labelled pixels (x, y)
    "1399145206": {"front head": (300, 153), "front torso": (294, 343), "front raised hand": (471, 184),
                   "back torso": (453, 367)},
    "82823944": {"front head": (239, 159), "front torso": (242, 343), "front left hand": (70, 245),
                 "front right hand": (425, 233), "back head": (515, 184), "back torso": (505, 367)},
    "1078881076": {"front head": (291, 159), "front fist a": (146, 324), "front fist b": (459, 300)},
}


@needs_assets
@pytest.mark.parametrize("name", sorted(SKELTRACK_POINTS))
def test_skeltrack_hands_and_overlapping_people_go_to_their_owner(name):
    """A hand in front of the other person, and fists cut off from the arm by a depth step
    (0.5 m nearer than the chest), belong to their owner's mask."""
    seg = segment_people(skeltrack_depth(name), KINECT)
    labels = labels_at(seg, SKELTRACK_POINTS[name])
    front = {labels[k] for k in labels if k.startswith("front")}
    back = {labels[k] for k in labels if k.startswith("back")}
    assert len(front) == 1 and 0 not in front
    if back:
        assert len(back) == 1 and not back & front
        near, far = seg.people[front.pop() - 1], seg.people[back.pop() - 1]
        assert near.centroid_m[2] + 0.4 < far.centroid_m[2]


def test_the_head_height_profile_is_scipys_binned_maximum_smoothed():
    from scipy.ndimage import maximum, uniform_filter1d

    from swarmpose.detect.people import height_profile

    rng = np.random.default_rng(3)
    for n_bins, dtype in ((1, np.float64), (2, np.float64), (7, np.float32), (40, np.float64), (40, np.float32)):
        bins = rng.integers(0, n_bins, 300)
        if n_bins > 2:
            bins[bins == 1] = 0  # an empty bin
        bins[-1] = n_bins - 1
        heights = rng.uniform(0.2, 1.9, 300).astype(dtype)  # the segmentation's are float32
        low = heights.min()
        expected = np.asarray(maximum(heights, bins, np.arange(n_bins)), dtype=np.float64)
        expected[np.bincount(bins, minlength=n_bins) == 0] = low
        expected = np.concatenate([[low], uniform_filter1d(expected, 3, mode="nearest"), [low]])
        np.testing.assert_allclose(height_profile(heights, bins), expected, rtol=0, atol=1e-12)
