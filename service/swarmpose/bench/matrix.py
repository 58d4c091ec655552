"""The cells of the accuracy benchmark: which views, motions, shapes and detectors it crosses.

The full cross product (5 yaws x 2 camera placements x 5 motions x 4 shapes x 3 detectors)
is 600 sequences-with-a-detector, days of CPU. The matrix samples it so that every yaw meets
every detector and every motion meets three yaws:

* sequence k = 3·i + j (yaw i of :data:`YAWS`, j = 0, 1, 2) films motion
  ``MOTIONS[(i + 2·j) % 5]`` on shape ``SHAPES[k % 4]`` from placement
  ``PLACEMENTS[(i + j) % 2]``: 15 sequences, each motion under 3 different yaws, each shape
  3-4 times, both placements under every yaw but one;
* each sequence is tracked with every detector of :data:`DETECTORS`: 45 cells;
* each cell in every mode of :data:`MODES`.

``subset="regression"`` is the small set ``make test`` runs: the walk seen from the side
(90°) and from behind (180°), and jumping jacks from behind on the heavy male (the cell whose
start locked into the mirrored facing when MoveNet swapped sides on its first frame), MoveNet.

``subset="hard"`` is the hard motions' own design (turning walk, sit-stand, run, pick-up, two
kicks at every yaw, MoveNet and BlazePose; :mod:`.hard_motions`), ``"hard-regression"`` its
small set for the slow test tier.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmpose.bench.hard_motions import HARD_MOTIONS, hard_plan
from swarmpose.core.errors import ConfigError

YAWS: tuple[int, ...] = (0, 45, 90, 135, 180)
"""Camera yaw around the subject (degrees; 0 = in front, 180 = behind)."""

PLACEMENTS: tuple[tuple[float, float], ...] = ((1.2, 3.0), (2.2, 4.0))
"""(lens height above the floor, distance from the subject) in metres: tripod, and wall-mounted."""

MOTIONS: dict[str, str] = {
    "walk": "mocap/bvh11_131_01.bvh",
    "hop": "mocap/animdrawings_fair1_jumping.bvh",
    "jumps-turns": "mocap/fairmotion_01_01.bvh",
    "jumping-jacks": "mocap/animdrawings_cmu1_jumping_jacks.bvh",
    "dance": "mocap/animdrawings_rokoko_jesse_dance.bvh",
}
"""Motion name -> BVH clip below the shared assets folder."""

SHAPES: tuple[str, ...] = ("male", "female", "male-heavy", "female-tall")
"""MakeHuman shape presets of the subjects (the tracker uses the subject's own shape)."""

DETECTORS: dict[str, str] = {
    "simulated": "simulated",
    "movenet": "onnx:{assets}/pose2d/movenet_singlepose_lightning.onnx",
    "blazepose": "onnx:{assets}/pose2d/blazepose_landmark_full.onnx",
}
"""Detector name -> detector spec ({assets}: the shared assets folder)."""

MODES: tuple[str, ...] = ("hybrid", "joints", "depth", "lift")

SUBSETS = ("full", "regression", "hard", "hard-regression")
SUBSET_DETECTORS: dict[str, tuple[str, ...]] = {"full": tuple(DETECTORS), "regression": ("movenet",),
                                                "hard": ("movenet", "blazepose"), "hard-regression": ("movenet",)}
"""The detectors a subset's cells use unless told otherwise."""


@dataclass(frozen=True)
class Sequence:
    """One synthetic sequence of the matrix: motion, subject shape, camera, and the props of the
    scene (``synth --prop`` specs)."""

    motion: str
    shape: str
    yaw_deg: int
    camera_height: float
    camera_distance: float
    props: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        return (f"{self.motion}-{self.shape}-yaw{self.yaw_deg:03d}"
                f"-h{self.camera_height:.1f}-d{self.camera_distance:.1f}"
                + "".join(f"-{p.replace(':', '_')}" for p in self.props))


@dataclass(frozen=True)
class Cell:
    """A sequence tracked with one detector (in every mode)."""

    sequence: Sequence
    detector: str

    @property
    def name(self) -> str:
        return f"{self.sequence.name}-{self.detector}"


def sequences(subset: str = "full") -> list[Sequence]:
    """The matrix's sequences (see the module docstring)."""
    if subset not in SUBSETS:
        raise ConfigError(f"unknown benchmark subset {subset!r}; choose one of {', '.join(SUBSETS)}")
    if subset in ("hard", "hard-regression"):
        return [Sequence(motion, shape, yaw, height, distance, HARD_MOTIONS[motion].props)
                for motion, shape, yaw, (height, distance) in hard_plan(YAWS, SHAPES, PLACEMENTS,
                                                                       subset == "hard-regression")]
    if subset == "regression":
        height, distance = PLACEMENTS[0]
        return ([Sequence("walk", "male", yaw, height, distance) for yaw in (90, 180)]
                + [Sequence("jumping-jacks", "male-heavy", 180, height, distance)])
    motions = list(MOTIONS)
    out = []
    for i, yaw in enumerate(YAWS):
        for j in range(3):
            k = 3 * i + j
            height, distance = PLACEMENTS[(i + j) % 2]
            out.append(Sequence(motions[(i + 2 * j) % len(motions)], SHAPES[k % len(SHAPES)], yaw, height, distance))
    return out


def cells(subset: str = "full", detectors: tuple[str, ...] | None = None,
          motions: tuple[str, ...] | None = None) -> list[Cell]:
    """Every (sequence, detector) of the subset; ``detectors`` limits them (names of :data:`DETECTORS`;
    default: the subset's, :data:`SUBSET_DETECTORS`), ``motions`` to the sequences of those motions."""
    seqs = sequences(subset)
    chosen = tuple(detectors) if detectors else SUBSET_DETECTORS[subset]
    unknown = [d for d in chosen if d not in DETECTORS]
    if unknown:
        raise ConfigError(f"unknown detector {unknown[0]!r} for the benchmark; choose from {', '.join(DETECTORS)}")
    if motions:
        present = list(dict.fromkeys(s.motion for s in seqs))
        missing = [m for m in motions if m not in present]
        if missing:
            raise ConfigError(f"motion {missing[0]!r} is not in the {subset!r} subset; choose from "
                              f"{', '.join(present)}")
        seqs = [s for s in seqs if s.motion in motions]
    return [Cell(seq, det) for seq in seqs for det in chosen]
