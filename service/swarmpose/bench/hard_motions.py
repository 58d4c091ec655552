"""The hard motions of the accuracy benchmark (issue 53): ``bench accuracy --subset hard``.

Six CMU clips of the Daz release (120 fps, resampled to 30 fps when read; each opens with a
T-pose frame, which every segment skips), each cut to the segment that holds its hard part
(seconds of the clip):

=============  ==============================================  =========  ==========================================
motion         clip                                             segment    what happens in it
=============  ==============================================  =========  ==========================================
turning-walk   ``cmu_06_10_dribble_walk_left_turns.bvh``        2.0–7.6    four 90° left turns on the spot while
                                                                           dribbling: the pelvis turns through 365°
sit-stand      ``cmu_14_31_sit_stepstool_standup.bvh``          1.2–8.0    backs onto a low stool, seated by 2.4 s,
                                                                           stands up 7.0–7.9 s (the stool rendered:
                                                                           ``synth --prop stool``, placed over the
                                                                           whole segment)
run            ``cmu_09_01_run.bvh``                            0.1–0.6    running at 3.6 m/s (1.8 m; the clip is 1.2 s)
pick-up        ``cmu_02_06_bend_scoop_pickup.bvh``              0.5–2.1    bends to the floor, scoops with the right
                                                                           hand, straightens up
soccer-kick    ``cmu_10_01_soccer_kick.bvh``                    4.3–5.6    the last run-up strides and the kick: the
                                                                           right foot swings up to 0.5 m twice
front-kick     ``cmu_135_04_front_kick.bvh``                    2.6–3.8    a right front kick (the foot 1.3 m up),
                                                                           landing a step forward
=============  ==============================================  =========  ==========================================

``--frames N`` tracks the first N frames of each segment (at most the segment). Each sequence
turns the clip so that the subject faces the camera at the segment's first frame when the
camera's yaw is 0 (the clip's own world frame is its T-pose's, which faces elsewhere).

The design (:func:`hard_plan`): motion m (in the order above) at every yaw i of the matrix's
yaws, on shape ``shapes[(m + i) % len(shapes)]`` (every motion meets four shapes), from
placement ``placements[(m + i) % 2]`` unless the motion travels (run and kicks: the far,
wall-mounted placement, so that the subject stays in view): 30 sequences, each tracked with
MoveNet and BlazePose. ``hard-regression`` is the turning walk's first turn seen from the
front with MoveNet, for the slow test tier.
"""

from __future__ import annotations

from dataclasses import dataclass

FPS = 30.0
"""The frame rate the benchmark films at (the clips are resampled to it)."""


@dataclass(frozen=True)
class HardMotion:
    """A clip below the shared assets folder, the segment that holds the hard motion (start and
    length, seconds of the clip), whether the subject travels far (then the far placement) and
    the props of the scene (``synth --prop`` specs)."""

    clip: str
    start_s: float
    seconds: float
    travels: bool = False
    props: tuple[str, ...] = ()

    @property
    def frames(self) -> int:
        """Frames of the segment at :data:`FPS`."""
        return int(round(self.seconds * FPS))


HARD_MOTIONS: dict[str, HardMotion] = {
    "turning-walk": HardMotion("mocap/cmu_06_10_dribble_walk_left_turns.bvh", 2.0, 5.6),
    "sit-stand": HardMotion("mocap/cmu_14_31_sit_stepstool_standup.bvh", 1.2, 6.8, props=("stool",)),
    "run": HardMotion("mocap/cmu_09_01_run.bvh", 0.1, 0.5, travels=True),
    "pick-up": HardMotion("mocap/cmu_02_06_bend_scoop_pickup.bvh", 0.5, 1.6),
    "soccer-kick": HardMotion("mocap/cmu_10_01_soccer_kick.bvh", 4.3, 1.3, travels=True),
    "front-kick": HardMotion("mocap/cmu_135_04_front_kick.bvh", 2.6, 1.2, travels=True),
}
"""Motion name -> its clip and segment (see the module doc)."""

HARD_REGRESSION = (("turning-walk", 0),)
"""(motion, yaw) of the ``hard-regression`` subset."""


def hard_plan(yaws: tuple[int, ...], shapes: tuple[str, ...], placements: tuple[tuple[float, float], ...],
              regression: bool = False) -> list[tuple[str, str, int, tuple[float, float]]]:
    """(motion, shape, yaw, (camera height, distance)) of every sequence of the hard design (the
    module doc), or of ``hard-regression``."""
    out = []
    for m, (motion, spec) in enumerate(HARD_MOTIONS.items()):
        for i, yaw in enumerate(yaws):
            if regression and (motion, yaw) not in HARD_REGRESSION:
                continue
            placement = placements[-1] if spec.travels else placements[(m + i) % len(placements)]
            out.append((motion, shapes[(m + i) % len(shapes)], yaw, placement))
    return out


def segment_frames(motion: str, frames: int) -> int:
    """Frames of ``motion`` a run of ``frames`` frames per sequence tracks: a hard motion's at
    most its segment's, any other motion's ``frames``."""
    spec = HARD_MOTIONS.get(motion)
    return frames if spec is None else min(frames, spec.frames)
