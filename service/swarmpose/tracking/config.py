"""What changes how a frame is tracked: :class:`TrackerConfig`, one declaration for the API,
every command's flags, the TOML file and ``SWARMPOSE_*`` (see :mod:`swarmpose.core.settings`)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import check_settings, setting

if TYPE_CHECKING:  # the objective (body model, scipy) is imported where the weights are asked for
    from swarmpose.tracking.objective import ObjectiveWeights
    from swarmpose.tracking.pso import PsoConfig

MODES = ("hybrid", "depth", "joints", "lift")
VARIANTS = ("canonical", "perturbed")
"""The PSO variants (:mod:`swarmpose.tracking.pso`)."""
SEARCHES = ("blocks", "swarm", "auto")
"""A tracked frame's search: block by block (:mod:`swarmpose.tracking.block_pso`), the paper's
whole-pose swarm (:mod:`swarmpose.tracking.pso`), or (auto) the former on a live frame with a frame
budget and the latter offline."""
SMOOTHING = ("off", "one-euro", "centred")
MODE_WEIGHTS = {"hybrid": (3.0, 1.0), "depth": (1.0, 0.0), "joints": (0.0, 1.0)}
"""(w_D, w_J) of each mode; ``lift`` fits no model."""


@dataclass(frozen=True)
class TrackerConfig:
    """The tracker's settings (paper §2.3-2.4 where it names them)."""

    mode: str = setting("hybrid", "objective: hybrid (w_D=3, w_J=1), depth (w_J=0), joints (w_D=0) or lift (J^e, no "
                                  "model)", choices=MODES)
    """depth mode: the joints still (re)start a track."""
    particles: int = setting(64, "PSO particles per generation", minimum=1)
    generations: int = setting(32, "PSO generations per frame (the paper's swarm: 64)", minimum=1)
    pso: str = setting("perturbed", "PSO variant", choices=VARIANTS)
    search: str = setting("blocks", "tracked frames: blocks (a particle moves one limb of a shared pose), swarm ("
                                    "the paper), auto (blocks live)", choices=SEARCHES)
    """Every tracked frame block by block (``generations`` 32; docs/tracking.md says why), offline but a
    fast-turning track's (``turning_swarm``); swarm with ``generations`` 64 is the paper's search. A
    track's start and frames where other facings compete search with the whole-pose swarm either way.
    The PSO variant's perturbation and the sub-swarms (``hypotheses``) are the whole-pose swarm's."""
    turning_swarm: float = setting(90.0, "offline, a track turning faster than this (deg/s) searches its frame with "
                                         "the whole-pose swarm (0 = never)", minimum=0)
    """Block by block, the limbs' sub-swarms follow a body that turns badly (each is judged in the
    shared pose, which the turn moves); the rate is the root's turn between the track's last two poses.
    Live frames keep the blocks: at a live frame's few generations the whole swarm loses more."""
    depth_weight: float | None = setting(None, "w_D (auto: the mode's)", kind="float?", minimum=0)
    joints_weight: float | None = setting(None, "w_J (auto: the mode's)", kind="float?", minimum=0)
    tile: tuple[int, int] = setting((64, 64), "depth tile WxH pixels over the person's box", kind="size")
    triangles: int = setting(1500, "tracking level of detail of the body mesh, triangles", minimum=100)
    coarse_share: float = setting(0.0, "share of each PSO's generations scored at the coarse tile and triangles "
                                       "(0 = off)", minimum=0.0, maximum=1.0)
    """Off by default: scoring generations on the coarse tile and mesh costs accuracy. Frames
    searched block by block (``search``) score at full resolution throughout."""
    coarse_tile: tuple[int, int] = setting((32, 32), "depth tile WxH pixels of the coarse generations", kind="size")
    coarse_triangles: int = setting(500, "level of detail of the body mesh in the coarse generations, triangles",
                                    minimum=100)
    max_people: int = setting(6, "track up to this many people (1: one person, no segmentation)", minimum=1,
                              maximum=32, everyday=True)
    """Each person is found in the depth and detected on a crop of their own."""
    box_hold: float = setting(0.0, "keep the 2D detector's crop box while the tracked joints' box moves less than "
                                   "this share (0 = off)", minimum=0.0, maximum=0.5)
    """Each edge may move this share of the box's larger side, once the box has stayed within it for
    5 frames. A network's keypoints move when its crop does, and the crop follows the track: on a
    person standing still, holding the box keeps that loop from feeding the track's jitter back
    into it (:mod:`swarmpose.detect.steady_boxes`; 0.02 measured in BENCHMARKS.md). Off by default:
    on moving sequences its effect was not shown to be nil (a fragile cell's flips, 5 of 12 seeds
    against 3)."""
    retire_frames: int = setting(30, "frames a person may go unseen (occluded, crossing) before its id is retired",
                                 minimum=0)
    personalize: int = setting(0, "fit each person's body shape on their first N tracked frames, then lock it "
                                  "(0 = off, else 3..300)", minimum=0, maximum=300)
    """Needs a body with a shape space: ``builtin`` or ``makehuman:DIR``."""
    seed: int = setting(0, "PSO seed (a run repeats exactly with the same seed)", minimum=0)
    start_budget: int = setting(64, "least particles and generations of a track's start, per facing", minimum=1)
    recheck: int = setting(10, "refit the start's facings every N frames and let them compete (0 = off)",
                           minimum=0)
    """Also on a new track's 1st, 2nd and 4th frame (:data:`swarmpose.tracking.facings.YOUNG_RECHECKS`)."""
    label_swaps: bool = setting(True, "a detected left/right pair may match the model's pair crossed, at a cost")
    """Detectors swap sides on people seen from behind."""
    penetration: float = setting(1.0, "w_P: cost per cm of an elbow or wrist inside the torso (0 = off)",
                                 minimum=0.0)
    arm_prior: float = setting(0.0, "w_A: cost per rad² of the arms away from rest, times how side-on the person "
                                    "stands (0 = off)", minimum=0.0)
    """1 holds the arms a side view hides."""
    limb_flips: bool = setting(True, "each limb of the last pose mirrored along the line of sight joins the swarm")
    """Same image, other depth: one particle per limb, every frame."""
    limb_exchanges: bool = setting(True, "side on, the last pose with its legs', and its arms', swings exchanged "
                                         "left for right joins the swarm")
    """For a track within 45° of side on, one particle per pair (:mod:`swarmpose.tracking.limb_exchanges`)."""
    arm_proposals: bool = setting(True, "each arm sent to unexplained depth within its reach joins the swarm")
    """Every frame, each arm of the last solution is sent to observed depth within its reach that the
    body does not explain, and to the other arm's mirror image; each such pose is a particle."""
    hypotheses: int = setting(2, "search swarm: the best N limb flips and arm proposals each refine in a "
                                 "sub-swarm first (0 = off)", minimum=0, maximum=4)
    """Searched block by block, every flip and proposal starts a particle of its limb's sub-swarm instead.
    Each sub-swarm has 3/16 of the particles (12 of 64) and refines its proposal apart from the
    track for the first 3/4 of the generations before they compete; 0: single particles."""
    hidden_lifts: bool = setting(True, "a joint hidden behind the body's own depth leaves the 3D joint term")
    """Its lift measured the occluder; the 2D term keeps it."""
    polish: int = setting(60, "rounds of local search (32 poses each) after each frame's search (0 = off)",
                          minimum=0)
    """They take the best pose's root, spine, neck and legs further down the same objective (on a
    young track the best of each facing, before they compete); the arms stay the search's. Off:
    faster, without that refinement."""
    backward: int = setting(0, "offline: every N frames refit each track backwards over them, published N frames "
                               "late (0 = off)", minimum=0)
    """A track's start and a side view's limbs settle over frames, which the backward pass starts
    with. Offline drivers only (:mod:`swarmpose.pipeline.features`); not with the lift mode or
    one-euro smoothing (centred smoothing runs after it)."""
    ensemble: int = setting(1, "offline: track every frame N times (seeds seed..seed+N-1) and publish the "
                               "mean (1 = off)", minimum=1, maximum=16)
    """The first track's people are published, each joint the confidence-weighted mean of the
    tracks' (the pose fitted to it): a joint the depth and the detector leave open lands elsewhere
    in each track, and their mean is nearer. N times the time per frame. Offline drivers only
    (:mod:`swarmpose.pipeline.features`); not with the backward pass or the lift mode."""
    auto_height: bool = setting(True, "scale a body whose shape is not given to each person's measured height")
    """Measured on the depth of their first upright frames; not with --shape or a .glb body."""
    smoothing: str = setting("off", "smooth the published poses: off, one-euro (live) or centred (offline)",
                             choices=SMOOTHING)
    """centred: each joint is read off a straight line fitted, Gaussian-weighted, through the
    person's positions of it within 3 sigma either side, the pose fitted to those joints; published
    3 sigma late. The search always starts from the unsmoothed pose."""
    smoothing_sigma_s: float = setting(0.05, "centred: the Gaussian's sigma in time, s (larger: steadier, "
                                             "fast motion flattened)", minimum=0.001, maximum=1.0)
    smoothing_cutoff_hz: float = setting(4.0, "One-Euro: the cut-off at rest, Hz (lower: steadier, more lag)",
                                         minimum=0.01)
    smoothing_beta: float = setting(10.0, "One-Euro: how fast the cut-off rises with speed, s per m or rad",
                                    minimum=0.0)
    """Higher: less lag in fast motion."""
    device: str = setting("", "OpenCL device: cpu, gpu, PLATFORM:DEVICE or part of its name (empty: a GPU, "
                              "else PoCL)", aliases=("cl_device",))
    alpha: float = setting(0.97, "share of the 2D term in E_J (the rest is the 3D term)", minimum=0.0, maximum=1.0)
    threshold_m: float = setting(0.30, "T: depth differences are clipped at this many metres", minimum=0.01)
    min_score: float = setting(0.3, "detected keypoints below this score are ignored", minimum=0.0, maximum=1.0)
    lost_joint_error: float = setting(0.12, "lost when the 2D joints are off by more than this share of the "
                                            "person's size", minimum=0.0)
    """Not while others hide part of the person and the depth agrees (several people)."""
    lost_depth_agreement: float = setting(0.4, "lost when fewer than this share of the model's pixels agree with "
                                               "the depth", minimum=0.0, maximum=1.0)

    def __post_init__(self) -> None:
        check_settings(self)
        if self.backward and self.mode == "lift":
            raise ConfigError(f"backward = {self.backward}: the backward pass refits a body model; the lift mode fits "
                              "none (use hybrid, depth or joints, or backward 0)")
        if self.backward and self.smoothing == "one-euro":
            raise ConfigError(f"backward = {self.backward} with smoothing {self.smoothing}: the backward pass "
                              "publishes its own fits, which the filter would have to run over backwards; choose "
                              "one (smoothing off or centred, or backward 0)")
        if self.ensemble > 1 and self.mode == "lift":
            raise ConfigError(f"ensemble = {self.ensemble}: the lift mode has no search whose tracks could differ (use "
                              "hybrid, depth or joints, or ensemble 1)")
        if self.ensemble > 1 and self.backward:
            raise ConfigError(f"ensemble = {self.ensemble} with backward = {self.backward}: the backward pass refits "
                              "one track; choose one (ensemble 1, or backward 0)")
        if self.smoothing == "centred" and self.mode == "lift":
            raise ConfigError("smoothing centred fits the body's pose to the smoothed joints; the lift mode fits "
                              "no body (use hybrid, depth or joints, or smoothing off)")
        if 0 < self.personalize < 3:
            raise ConfigError(f"personalize = {self.personalize}: a shape needs at least 3 tracked frames "
                              "(0 turns personalisation off)")

    def refine_at(self, generations: int) -> int:
        """The generation of a ``generations``-long PSO from which it scores at full resolution
        (0: all of them)."""
        return min(int(round(self.coarse_share * generations)), generations)

    @property
    def centred_sigma_s(self) -> float:
        """σ (s) of the centred smoothing of recordings (:mod:`swarmpose.pipeline.centred_smoothing`), 0
        when it is not asked for."""
        return self.smoothing_sigma_s if self.smoothing == "centred" else 0.0

    @property
    def pso_config(self) -> PsoConfig:
        """The swarm's size, budget and variant."""
        from swarmpose.tracking.pso import PsoConfig

        return PsoConfig(particles=self.particles, generations=self.generations, variant=self.pso)

    @property
    def weights(self) -> ObjectiveWeights:
        """w_D, w_J (the mode's unless given), alpha, T and the score threshold."""
        from swarmpose.tracking.objective import ObjectiveWeights

        w_d, w_j = MODE_WEIGHTS.get(self.mode, (0.0, 1.0))
        return ObjectiveWeights(depth=w_d if self.depth_weight is None else self.depth_weight,
                                joints=w_j if self.joints_weight is None else self.joints_weight,
                                alpha=self.alpha, threshold_m=self.threshold_m, min_score=self.min_score,
                                label_swaps=self.label_swaps, penetration=self.penetration,
                                arm_prior=self.arm_prior)


def tracker_default(name: str) -> Any:
    """The default of :class:`TrackerConfig`'s setting ``name``: the one place a tracker default is
    declared; the PSO's and the objective's own defaults are read from here."""
    for f in fields(TrackerConfig):
        if f.name == name:
            return f.default
    raise KeyError(f"TrackerConfig has no setting {name!r}")
