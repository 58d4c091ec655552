"""``utdmhad:PATH/aA_sS_tT_depth.mat``: a UTD-MHAD sequence (real Kinect v1 depth of a real
person) with the Kinect SDK skeleton beside it as ground truth.

UTD-MHAD (Chen, Jafari & Kehtarnavaz, ICIP 2015) ships per sequence a MATLAB file with
``d_depth`` (240 x 320 x F, uint16 mm, background removed) and one with ``d_skel``
(20 x 3 x F, metres, Kinect SDK camera coordinates: x to the sensor's left, y up, z
forward). The skeleton file is looked for beside the depth file and in ``../skeleton/``
(the dataset's layout), named ``aA_sS_tT_skeleton.mat``.

Conventions of this source:

* **Un-mirrored**: Kinect v1 images are mirrored (the sensor's left on the image's right).
  Every depth image is flipped left-right, and skeleton points become (−x, −y, z) in
  swarmpose's camera frame (x right, y down, z forward), so a person's left is their left
  and a network's "left_wrist" means the same wrist as the skeleton's.
* **Intrinsics**: none ship with the data; the nominal Kinect v1 depth camera at 320 x 240,
  f = 285.63 px, principal point (159, 120) after the flip (:data:`INTRINSICS`).
* **Colour**: there is none; ``color`` is the depth shaded as a surface
  (:func:`~swarmpose.sources.depth_shading.shaded_normals`) so RGB pose networks can run.
* **Ground truth** (``ground_truth``): the skeleton mapped to the evaluation joints by
  :data:`EVAL_FROM_KINECT` (Kinect's shoulder_center is our neck; its hip joints sit higher
  and wider than a rig's hip centres, its head is the head's centre) and the projected
  skeleton points (``points2d``) from which ``--detector simulated`` draws its noisy
  keypoints. There is no pose vector (``poses`` is NaN).
* **In time with the depth**: the files pair depth frame ``t`` with a skeleton 1.75 frames
  ahead of it (:mod:`.utdmhad_sync` measures that on the data). The ground truth and the
  simulated detector's keypoints of frame ``t`` are the skeleton at ``t − lag`` (interpolated);
  ``lag`` is :data:`~swarmpose.sources.utdmhad_sync.DEPTH_LAG_FRAMES` unless the URI says
  otherwise: ``utdmhad:FILE.mat?lag=0`` keeps the files' pairing.
* Frames are 30 per second (timestamps ``index`` x 33.3 ms).

Errors (:class:`~swarmpose.core.errors.SourceError`, exit 2): a file that is not a MATLAB
file or lacks ``d_depth`` / ``d_skel`` of the right shapes, a missing skeleton file, depth
and skeleton of different frame counts; :class:`~swarmpose.core.errors.ConfigError`: a ``lag``
that is not a number of frames within 0..10.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import SourceError
from swarmpose.sources.base import Frame, FrameSource, SkippedFrame
from swarmpose.sources.depth_shading import shaded_normals
from swarmpose.sources.groundtruth import GroundTruth
from swarmpose.sources.utdmhad_sync import DEPTH_LAG_FRAMES, check_lag, synchronised

WIDTH, HEIGHT = 320, 240
INTRINSICS = Intrinsics(WIDTH, HEIGHT, 285.63, 285.63, WIDTH - 1 - 160.0, 120.0)
"""The nominal Kinect v1 depth camera at 320 x 240, principal point after the left-right flip."""

FRAME_PERIOD_NS = 33_333_333
"""Kinect v1 at 30 frames/s."""

KINECT_JOINTS: tuple[str, ...] = (
    "head", "shoulder_center", "spine", "hip_center",
    "left_shoulder", "left_elbow", "left_wrist", "left_hand",
    "right_shoulder", "right_elbow", "right_wrist", "right_hand",
    "left_hip", "left_knee", "left_ankle", "left_foot",
    "right_hip", "right_knee", "right_ankle", "right_foot",
)
"""The 20 joints of ``d_skel`` in the dataset's order (``Skeleton_joint_order.txt``)."""

EVAL_FROM_KINECT: dict[str, str] = {
    "head": "head", "neck": "shoulder_center",
    **{f"{side}_{j}": f"{side}_{j}" for side in ("left", "right")
       for j in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")},
}
"""Evaluation joint -> the Kinect joint it is compared with."""

SIMULATED_POINTS: dict[str, str] = {
    **{f"{side}_{j}": f"{side}_{j}" for side in ("left", "right")
       for j in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")},
    "neck": "shoulder_center",
}
"""Body point -> Kinect joint, for the simulated detector (the skeleton has no face points)."""

_NAME = re.compile(r"^(a\d+_s\d+_t\d+)_depth\.mat$")


def skeleton_file(depth_file: Path) -> Path:
    """The skeleton file of ``depth_file`` (beside it, else in ``../skeleton/``); SourceError when neither exists."""
    match = _NAME.match(depth_file.name)
    if match is None:
        raise SourceError(f"utdmhad: {depth_file} is not named like a UTD-MHAD depth file (aA_sS_tT_depth.mat); "
                          "pass the dataset's depth .mat file")
    name = f"{match.group(1)}_skeleton.mat"
    candidates = [depth_file.with_name(name), depth_file.parent.parent / "skeleton" / name]
    for path in candidates:
        if path.is_file():
            return path
    raise SourceError(f"utdmhad: no skeleton file for {depth_file} (looked for {candidates[0]} and "
                      f"{candidates[1]}); UTD-MHAD's skeleton/ folder must sit beside depth/")


def _load_variable(path: Path, variable: str, kind: str) -> np.ndarray:
    from scipy.io import loadmat

    try:
        data = loadmat(str(path), variable_names=[variable])
    except Exception as exc:  # scipy raises ValueError, TypeError, MatReadError... for what is not MATLAB
        raise SourceError(f"utdmhad: cannot read {path} as a MATLAB file ({type(exc).__name__}: {exc}); "
                          f"pass a UTD-MHAD {kind} .mat file") from exc
    if variable not in data:
        raise SourceError(f"utdmhad: {path} has no variable {variable!r}, so it is not a UTD-MHAD {kind} file")
    return np.asarray(data[variable])


def read_depth(path: Path) -> np.ndarray:
    """Depth images (F, 240, 320) float32 metres of a UTD-MHAD depth file, flipped left-right (0 = no person)."""
    raw = _load_variable(path, "d_depth", "depth")
    if raw.ndim != 3 or raw.shape[:2] != (HEIGHT, WIDTH) or raw.shape[2] < 1:
        raise SourceError(f"utdmhad: d_depth in {path} is {raw.shape}, not {HEIGHT} x {WIDTH} x frames")
    depth = np.moveaxis(raw, 2, 0).astype(np.float32) / 1000.0
    return np.ascontiguousarray(depth[:, :, ::-1])


def read_skeleton(path: Path) -> np.ndarray:
    """Kinect joints (F, 20, 3) metres in swarmpose's camera frame (x right, y down, z forward,
    un-mirrored); NaN for joints the Kinect did not track (written as 0, 0, 0)."""
    raw = _load_variable(path, "d_skel", "skeleton")
    if raw.ndim != 3 or raw.shape[:2] != (len(KINECT_JOINTS), 3) or raw.shape[2] < 1:
        raise SourceError(f"utdmhad: d_skel in {path} is {raw.shape}, not {len(KINECT_JOINTS)} x 3 x frames")
    skeleton = np.moveaxis(raw.astype(np.float64), 2, 0) * np.array([-1.0, -1.0, 1.0])
    skeleton[~(skeleton[..., 2] > 0)] = np.nan
    return skeleton


def ground_truth(skeleton: np.ndarray, intrinsics: Intrinsics = INTRINSICS) -> GroundTruth:
    """The :class:`GroundTruth` of Kinect joints (F, 20, 3): evaluation joints and projected points."""
    index = {name: i for i, name in enumerate(KINECT_JOINTS)}
    joints3d = skeleton[:, [index[EVAL_FROM_KINECT[j]] for j in EVAL_JOINTS]]
    points = skeleton[:, [index[k] for k in SIMULATED_POINTS.values()]]
    pixels = intrinsics.project(points.reshape(-1, 3)).reshape(*points.shape[:2], 2)
    points2d = tuple({name: pixels[f, i] for i, name in enumerate(SIMULATED_POINTS)} for f in range(len(skeleton)))
    frames = tuple(range(len(skeleton)))
    return GroundTruth(frames, np.full((len(frames), 36), np.nan), joints3d, (None,) * len(frames), points2d)


def measured_height(depth: np.ndarray, intrinsics: Intrinsics = INTRINSICS) -> float:
    """A standing person's height (m) from one background-free depth image (H, W) m.

    The person's points are back-projected; their extent along the first principal axis
    (the body's long axis when standing with the arms down, as UTD-MHAD's sequences begin),
    from the 0.5th to the 99.5th percentile, is the height. SourceError when fewer than
    500 pixels hold depth. Clamped to the body model's 1.2..2.3 m.
    """
    points = intrinsics.point_map(np.asarray(depth, dtype=np.float64)).reshape(-1, 3)
    points = points[np.isfinite(points[:, 2])]
    if len(points) < 500:
        raise SourceError(f"cannot measure a height: only {len(points)} pixels hold depth (need 500)")
    centred = points - points.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    along = centred @ axis
    lo, hi = np.percentile(along, [0.5, 99.5])
    return float(np.clip(hi - lo, 1.2, 2.3))


class UtdMhadSource(FrameSource):
    """The frames of one UTD-MHAD depth file (see the module docstring); everything is read when opened.

    Attributes beyond :class:`FrameSource`'s: ``intrinsics``, ``ground_truth`` (the skeleton
    ``lag_frames`` behind, in time with the depth), ``skeleton`` (F, 20, 3) the file's Kinect
    joints in our camera frame as paired in the file, ``depth_file``, ``skeleton_file``.
    ``replays_detections`` is False: the skeleton is what a run is measured against, so
    ``--detector auto`` runs a network on the shaded depth rather than replay it (``simulated`` does).
    """

    replays_detections = False

    def __init__(self, path: str | Path, uri: str | None = None, lag_frames: float = DEPTH_LAG_FRAMES):
        self.lag_frames = check_lag(lag_frames, str(path))
        self.depth_file = Path(path).expanduser()
        self.uri = uri or f"utdmhad:{self.depth_file}"
        if not self.depth_file.is_file():
            raise SourceError(f"utdmhad: file {self.depth_file} does not exist; pass PATH/aA_sS_tT_depth.mat "
                              "of UTD-MHAD")
        self.depth = read_depth(self.depth_file)
        self.skeleton_file = skeleton_file(self.depth_file)
        self.skeleton = read_skeleton(self.skeleton_file)
        if len(self.depth) != len(self.skeleton):
            raise SourceError(f"utdmhad: {self.depth_file} has {len(self.depth)} depth frames but "
                              f"{self.skeleton_file} has {len(self.skeleton)} skeletons; they must match one to one")
        self.intrinsics = INTRINSICS
        self.length = len(self.depth)
        self.ground_truth = ground_truth(synchronised(self.skeleton, self.lag_frames), self.intrinsics)

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        for i, depth in enumerate(self.depth):
            yield Frame(i, i * FRAME_PERIOD_NS, depth, shaded_normals(depth, self.intrinsics), self.intrinsics)
