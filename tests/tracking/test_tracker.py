"""The tracker on a synthetic sequence against its ground truth, its modes, and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import LAYOUTS
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, TrackingError
from swarmpose.detect.joints import Joints2D
from swarmpose.messages import validate
from swarmpose.motion.builtin import builtin_motion
from swarmpose.sim.synth import SynthConfig, synthesize
from swarmpose.sources.base import Frame
from swarmpose.sources.groundtruth import load_ground_truth
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.pose_polish import WITHOUT_ARMS
from swarmpose.tracking.result import FrameResult

FRAMES = 6
SMALL = {"particles": 24, "generations": 24}


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


@pytest.fixture(scope="module")
def sequence(tmp_path_factory, body) -> Path:
    out = tmp_path_factory.mktemp("walk")
    config = SynthConfig(frames=FRAMES, fps=15.0, seed=4)
    synthesize(body, builtin_motion("walk", FRAMES, config.fps), out, config, progress=False)
    return out


def frames_of(folder: Path):
    """(Frame, Joints2D) pairs read straight from the files (cv2), independent of the sources."""
    intr = Intrinsics.load(folder / "intrinsic.json")
    gt = load_ground_truth(folder)
    for row, f in enumerate(gt.frames):
        depth = cv2.imread(str(folder / "depth" / f"{f:06d}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000
        layout, kp = gt.detections[row]
        yield Frame(f, f * 66_666_667, depth, None, intr), Joints2D(LAYOUTS[layout], kp, f, 0)


def track(body, folder: Path, **config):
    intr = Intrinsics.load(folder / "intrinsic.json")
    tracker = BodyTracker(body, intr, TrackerConfig(**{**SMALL, **config}))
    return [tracker.step(frame, det) for frame, det in frames_of(folder)]


def errors_mm(results, folder: Path) -> np.ndarray:
    gt = load_ground_truth(folder)
    return 1000 * np.linalg.norm(np.array([r.joints3d for r in results]) - gt.joints3d, axis=2)


@pytest.mark.slow
def test_hybrid_tracks_the_walk_without_initialisation(body, sequence):
    results = track(body, sequence)
    assert [r.state for r in results] == ["init"] + ["tracking"] * (FRAMES - 1)
    err = errors_mm(results, sequence)
    assert np.mean(err) < 60, np.round(np.mean(err, axis=0))
    conf = np.array([r.confidence for r in results])
    assert np.all((conf >= 0) & (conf <= 1)) and conf.mean() > 0.5
    message = FrameResult(FRAMES - 1, 0, (results[-1],)).to_message("cam0")
    line = json.dumps(message, allow_nan=False)
    assert validate(json.loads(line))["bodies"][0]["state"] == "tracking"
    assert set(results[-1].objective) == {"E", "E_D", "E_J", "E_J2D", "E_J3D", "E_P", "E_A"}


@pytest.mark.slow
def test_seeded_runs_repeat(body, sequence):
    a = track(body, sequence, seed=3)[:2]
    b = track(body, sequence, seed=3)[:2]
    assert all(np.array_equal(x.pose, y.pose) for x, y in zip(a, b))


@pytest.mark.slow
def test_modes(body, sequence):
    lift = track(body, sequence, mode="lift")
    err = errors_mm(lift, sequence)
    assert np.nanmedian(err) < 80 and np.isfinite(err).mean() > 0.8
    assert all(r.pose is None for r in lift)
    joints = track(body, sequence, mode="joints")
    assert np.mean(errors_mm(joints, sequence)) < 90, np.mean(errors_mm(joints, sequence))
    assert all(r.objective["E_D"] == 0 for r in joints)
    depth = track(body, sequence, mode="depth")
    assert all(r.objective["E_J"] == 0 for r in depth[1:])
    with pytest.raises(ConfigError):
        TrackerConfig(mode="magic")


def test_no_person_then_recovery(body, sequence):
    intr = Intrinsics.load(sequence / "intrinsic.json")
    tracker = BodyTracker(body, intr, TrackerConfig(**SMALL))
    (frame, det), (frame1, det1) = list(frames_of(sequence))[:2]
    empty = Frame(0, 0, np.zeros_like(frame.depth), None, intr)
    r = tracker.step(empty, None)
    assert r.state == "lost" and "no person" in r.reason and r.pose is None
    none = Joints2D(det.layout, np.zeros_like(det.keypoints), 0, 0)
    r = tracker.step(frame, none)
    assert r.state == "lost" and r.pose is None
    r = tracker.step(frame, det)
    assert r.state == "init"
    r = tracker.step(frame1, none)  # all joints missing: depth alone carries the track
    assert r.state == "tracking" and "depth only" in r.reason
    nan_depth = Frame(2, 0, np.full_like(frame.depth, np.nan), None, intr)
    r = tracker.step(nan_depth, none)
    assert r.state == "lost" and r.reason
    with pytest.raises(TrackingError):
        tracker.step(Frame(3, 0, np.zeros((10, 10), np.float32), None, intr), det)


@pytest.mark.slow
def test_an_absurd_detection_does_not_stop_the_track(body, sequence):
    """Keypoints at NaN, at infinity and a million pixels away, all with high scores: the frame
    is tracked on what is left (depth), without an exception, and the next good detection
    keeps the track."""
    intr = Intrinsics.load(sequence / "intrinsic.json")
    tracker = BodyTracker(body, intr, TrackerConfig(**SMALL))
    (frame, det), (frame1, _), (frame2, det2) = list(frames_of(sequence))[:3]
    assert tracker.step(frame, det).state == "init"
    keypoints = np.zeros_like(det.keypoints)
    keypoints[:, 2] = 0.95
    keypoints[0::3, :2] = np.nan
    keypoints[1::3, :2] = np.inf
    keypoints[2::3, :2] = 1e6
    absurd = tracker.step(frame1, Joints2D(det.layout, keypoints, 1, 0))
    assert absurd.state == "tracking" and np.all(np.isfinite(absurd.joints3d))
    after = tracker.step(frame2, det2)
    assert after.state == "tracking"
    truth = load_ground_truth(sequence).joints3d[2]
    assert 1000 * np.mean(np.linalg.norm(after.joints3d - truth, axis=1)) < 120


@pytest.mark.slow
def test_coarse_to_fine_tracks_and_ends_at_full_resolution(body, sequence):
    """With a coarse share the search scores most generations on the coarse level, the last at
    full resolution (the reported E_D is the full level's), and still tracks the walk."""
    results = track(body, sequence, coarse_share=0.75, coarse_tile=(24, 24), coarse_triangles=300)
    assert [r.state for r in results] == ["init"] + ["tracking"] * (FRAMES - 1)
    assert np.mean(errors_mm(results, sequence)) < 60
    intr = Intrinsics.load(sequence / "intrinsic.json")
    tracker = BodyTracker(body, intr, TrackerConfig(**{**SMALL, "coarse_share": 0.75}))
    assert tracker.objective.coarse.tw == 32 and len(tracker.objective.coarse.body.triangles) <= 500
    frame, det = next(frames_of(sequence))
    result = tracker.step(frame, det)
    assert not tracker.objective.coarse_active
    tracker.objective(result.pose[None])  # scored again at full resolution: the same E_D
    assert tracker.objective.last_parts["E_D"][0] == pytest.approx(result.objective["E_D"], rel=1e-6)


def test_root_turn_is_the_angle_between_root_orientations():
    """By hand: quarter and half turns about the vertical, the quaternion's sign and scale do not
    matter, and a track replaced by its mirror (180°) counts as a turn past REPLACED_TURN_DEG."""
    from swarmpose.body.kinematics import root_turn_deg
    from swarmpose.tracking.body_tracker import REPLACED_TURN_DEG

    def about_y(deg: float, scale: float = 1.0) -> np.ndarray:
        pose = np.zeros(36)
        half = np.radians(deg) / 2
        pose[3:7] = scale * np.array([np.cos(half), 0.0, np.sin(half), 0.0])  # (w, x, y, z)
        return pose

    assert root_turn_deg(about_y(0), about_y(30)) == pytest.approx(30.0)
    assert root_turn_deg(about_y(10), about_y(100, scale=-2.0)) == pytest.approx(90.0)
    mirrored = root_turn_deg(about_y(-20), about_y(160))
    assert mirrored == pytest.approx(180.0) and mirrored > REPLACED_TURN_DEG


def test_a_turned_solution_replaces_the_track_only_when_it_wins_twice():
    """_hold_facing by hand: a frame whose best is the mirrored facing publishes the best particle
    of the track's own facing and keeps the mirror as the challenger; the mirror winning the next
    frame too replaces the track and drops the old poses from the seeds; a frame the track's
    facing wins clears the challenger."""
    from swarmpose.tracking.pso import PsoResult

    body = load_body("builtin", "default")
    tracker = BodyTracker(body, Intrinsics.kinect_v1(), TrackerConfig(mode="lift", smoothing="one-euro"))
    front, back = body.rest_pose((0.0, 0.0, 3.0), (0.0, 1.0, 0.0, 0.0)), body.rest_pose((0.0, 0.0, 3.0))
    own = front.copy()
    own[10] = 0.2  # another pose of the track's facing
    tracker.filter(front, 0.0)  # the smoothing has seen the old track
    mirrored_wins = PsoResult(back, 1.0, np.array([1.0]), 3, np.stack([back, own, back]), np.array([1.0, 2.0, 1.5]))
    tracker.previous = front
    tracker.history.restart(front)
    np.testing.assert_array_equal(tracker._hold_facing(mirrored_wins), own)
    assert tracker.challenger is back and tracker.history.poses == [front]
    np.testing.assert_array_equal(tracker._hold_facing(mirrored_wins), back)  # twice running: replaced
    assert tracker.challenger is None and len(tracker.history) == 0
    np.testing.assert_allclose(tracker.filter(back, 1 / 30), back)  # the filter starts afresh: no blend
    tracker.challenger = back
    track_wins = PsoResult(own, 1.0, np.array([1.0]), 3, np.stack([own, back]), np.array([1.0, 1.5]))
    np.testing.assert_array_equal(tracker._hold_facing(track_wins), own)
    assert tracker.challenger is None


def test_rechecks_are_due_every_n_frames_and_on_a_young_tracks_first_frames():
    from swarmpose.tracking.facings import recheck_due

    due = [k for k in range(1, 31) if recheck_due(100 + k, k, 10)]
    assert due == [1, 2, 4, 10, 20, 30]
    assert not any(recheck_due(k, k, 0) for k in range(1, 30))  # --recheck 0: none at all


def miss_px(body, intrinsics: Intrinsics, targets, pose: np.ndarray) -> float:
    """The median image distance (px) of ``pose``'s points to the detected joints of ``targets``."""
    pixels = intrinsics.project(body.posed_points(pose[None], targets.names)[0])
    return float(np.median(np.linalg.norm(pixels - targets.xy, axis=1)))


def recording_searches(tracker: BodyTracker) -> list[bool]:
    """Wraps ``tracker.pso_search``: the list it fills, per search, with whether its objective renders depth."""
    kinds, real = [], tracker.pso_search

    def search(objective, *args, **kwargs):
        kinds.append(objective.weights.depth > 0)
        return real(objective, *args, **kwargs)

    tracker.pso_search = search
    return kinds


def test_a_live_recheck_fits_the_joints_alone(body, sequence):
    """A re-check's facings: offline a joint-term PSO then a full-objective PSO from each (8 searches
    for 4 facings); live (a frame budget) the joint-term PSO alone (4). Either way the best fit has come
    to the detected joints."""
    from swarmpose.tracking.facings import fit_facings
    from swarmpose.tracking.init_pose import FACINGS_DEG, torso_pose
    from swarmpose.tracking.objective import JointTargets

    (frame, det), = [pair for k, pair in enumerate(frames_of(sequence)) if k == 2]
    depth = frame.depth.astype(np.float32)
    targets = JointTargets.from_detection(det, depth, frame.intrinsics, body, 0.3)
    centre = torso_pose(body, dict(zip(targets.names, targets.xyz)), body.rest_angles)
    for budget_ms, searches in ((0.0, 2 * len(FACINGS_DEG)), (60.0, len(FACINGS_DEG))):
        tracker = BodyTracker(body, frame.intrinsics, TrackerConfig(**SMALL, seed=1))
        tracker.budget_ms = budget_ms
        kinds = recording_searches(tracker)
        fits = fit_facings(tracker, centre, targets, depth, np.random.default_rng(0), {}, generations=4)
        assert len(kinds) == searches and kinds.count(False) == len(FACINGS_DEG)  # the joint stage: every facing
        start_px = miss_px(body, frame.intrinsics, targets, centre)
        assert miss_px(body, frame.intrinsics, targets, fits[0]) < 0.7 * start_px  # 7-9 px against 14


def test_a_short_live_frame_seeds_the_limbs_at_their_lifts_and_an_offline_one_does_not(body, sequence):
    """Live (a frame budget) with fewer than LEAN_BELOW generations a tracked frame adds the limb seeds
    of :mod:`swarmpose.tracking.lifted_limbs`; offline the same search does not."""
    intr = Intrinsics.load(sequence / "intrinsic.json")
    for budget_ms, seeded in ((60.0, True), (0.0, False)):
        tracker = BodyTracker(body, intr, TrackerConfig(particles=24, generations=8))
        tracker.budget_ms, tracker.frame_period_s = budget_ms, 1 / 15
        results = [tracker.step(frame, det) for frame, det in frames_of(sequence)]
        assert all(r.state != "lost" for r in results)
        assert [("lifted" in r.timings_ms) for r in results[1:]] == [seeded] * (FRAMES - 1)


def test_a_live_frame_is_seeded_where_the_motion_leads_and_an_offline_one_only_after_dropped_frames(body, sequence):
    """Every frame of the sequence (15 fps), one camera period apart: live (a frame budget) each tracked
    frame after the second gets the last two poses' prediction as a seed; offline none does."""
    intr = Intrinsics.load(sequence / "intrinsic.json")
    for budget_ms, seeded in ((60.0, True), (0.0, False)):
        tracker = BodyTracker(body, intr, TrackerConfig(particles=24, generations=8))
        tracker.budget_ms, tracker.frame_period_s = budget_ms, 1 / 15
        seeds, real = [], tracker.history.predicted

        def predicted(time_ns, periods, every_step=False, seeds=seeds, real=real):
            seeds.append(real(time_ns, periods, every_step))
            return seeds[-1]

        tracker.history.predicted = predicted
        results = [tracker.step(frame, det) for frame, det in frames_of(sequence)]
        assert all(r.state != "lost" for r in results)
        assert len(seeds) == FRAMES - 1, "every tracked frame after the start"
        assert [len(s) for s in seeds[1:]] == [int(seeded)] * (FRAMES - 2), budget_ms  # frame 1: one pose kept


def searched_by_blocks(tracker: BodyTracker) -> list[bool]:
    """The ``blocks`` argument of each of ``tracker``'s searches, recorded as they run."""
    seen, real = [], tracker.pso_search

    def search(objective, start, rng, pso, groups=None, blocks=False, proposals=()):
        seen.append(blocks)
        return real(objective, start, rng, pso, groups, blocks, proposals)

    tracker.pso_search = search
    return seen


def test_a_live_tracked_frame_searches_block_by_block_and_an_offline_one_with_the_whole_swarm(body, sequence,
                                                                                               monkeypatch):
    """``search`` auto (the default): with a frame budget a tracked frame's swarm runs block by block
    after its first generations (:mod:`swarmpose.tracking.block_pso`), except where re-checked facings
    compete (a young track's frames 1, 2 and 4) and at the start; offline every search is the
    whole-pose swarm's, as with ``search`` swarm; ``search`` blocks searches block by block offline
    too (``turning_swarm`` off: a fast turn offline searches with the whole swarm). Each follows the
    walker (31-32 mm measured)."""
    import swarmpose.tracking.block_pso as block_pso
    import swarmpose.tracking.body_tracker as body_tracker

    intr = Intrinsics.load(sequence / "intrinsic.json")
    for search, budget_ms, by_blocks in (("auto", 60.0, True), ("auto", 0.0, False), ("blocks", 0.0, True),
                                         ("swarm", 60.0, False)):
        tracker = BodyTracker(body, intr, TrackerConfig(particles=24, generations=8, search=search, turning_swarm=0))
        tracker.budget_ms, tracker.frame_period_s = budget_ms, 1 / 15
        seen, ran = searched_by_blocks(tracker), []
        monkeypatch.setattr(body_tracker, "whole_then_blocks",
                            lambda *args, real=block_pso.whole_then_blocks, ran=ran: ran.append(1) or real(*args))
        results = [tracker.step(frame, det) for frame, det in frames_of(sequence)]
        assert all(r.state != "lost" for r in results)
        quiet = [r for r in results[1:] if "recheck" not in r.timings_ms]  # tracked, no facing re-checked
        assert quiet and seen.count(True) == len(ran) == (len(quiet) if by_blocks else 0), (search, budget_ms)
        assert errors_mm(results, sequence).mean() < 50.0


def test_an_offline_recheck_refits_the_facings_on_a_quarter_of_the_start_budget(body, sequence):
    """Offline a re-check's facing fits run a quarter of ``start_budget`` generations when the frame's
    own search is smaller (24 // 4 = 6, not 8 // 4 = 2): a re-check must be able to replace a track
    started mirrored whatever the frame's budget."""
    intr = Intrinsics.load(sequence / "intrinsic.json")
    tracker = BodyTracker(body, intr, TrackerConfig(particles=24, generations=8, start_budget=24))
    sizes, real = [], tracker.pso_search

    def search(objective, start, rng, pso, *args, **kwargs):
        sizes.append(pso.generations)
        return real(objective, start, rng, pso, *args, **kwargs)

    tracker.pso_search = search
    frames = list(frames_of(sequence))
    tracker.step(*frames[0])
    sizes.clear()
    result = tracker.step(*frames[1])  # a young track's first re-check
    assert "recheck" in result.timings_ms
    assert 6 in sizes and 2 not in sizes and sizes[-1] == 8  # the facings' fits, then the frame's own search


def started_with_sizes(body, intr, frame, det, budget_ms: float, monkeypatch):
    """A track started on ``frame`` (40 generations, 20 polish rounds configured) with a frame budget of
    ``budget_ms``: (its result, the generations of its last search, the polish rounds it ran)."""
    import swarmpose.tracking.body_tracker as body_tracker

    tracker = BodyTracker(body, intr, TrackerConfig(particles=24, generations=40, polish=20, start_budget=24))
    tracker.budget_ms = budget_ms
    searches, polished = [], []
    real_search, real_polish = tracker.pso_search, body_tracker.polish_solution

    def search(objective, start, rng, pso, *args, **kwargs):
        searches.append(pso.generations)
        return real_search(objective, start, rng, pso, *args, **kwargs)

    def polish(objective, result, previous, rounds, *args):
        polished.append(rounds)
        return real_polish(objective, result, previous, rounds, *args)

    tracker.pso_search = search
    monkeypatch.setattr(body_tracker, "polish_solution", polish)
    return tracker.step(frame, det), searches[-1], polished


def test_a_live_start_runs_a_short_search_after_the_facings_and_an_offline_one_the_configured(
        body, sequence, monkeypatch):
    """A track's start with 40 generations and 20 polish rounds configured: offline its swarm after the
    facings' fits runs 40 generations and the polish 20 rounds; live (a frame budget) 16 and 8. Either way
    the start finds the walker (mean joint error under 80 mm)."""
    from swarmpose.tracking.budget import LIVE_START_GENERATIONS, LIVE_START_POLISH

    intr = Intrinsics.load(sequence / "intrinsic.json")
    (frame, det), = [pair for k, pair in enumerate(frames_of(sequence)) if k == 0]
    truth = load_ground_truth(sequence).joints3d[0]
    for budget_ms, generations, rounds in ((0.0, 40, 20), (60.0, LIVE_START_GENERATIONS, LIVE_START_POLISH)):
        result, searched, polished = started_with_sizes(body, intr, frame, det, budget_ms, monkeypatch)
        assert result.state == "init"
        assert (searched, polished) == (generations, [rounds])
        assert 1000 * np.mean(np.linalg.norm(result.joints3d - truth, axis=1)) < 80


def test_a_different_turned_solution_becomes_the_challenger_and_reset_forgets_it():
    """Frame k's best is the mirror, frame k+1's best another turned pose (neither the track's
    facing nor the challenger's): it does not replace the track but becomes the challenger;
    reset() forgets the challenger and the track's age."""
    from scipy.spatial.transform import Rotation

    from swarmpose.body.kinematics import root_turn_deg
    from swarmpose.tracking.body_tracker import REPLACED_TURN_DEG
    from swarmpose.tracking.pso import PsoResult

    body = load_body("builtin", "default")
    tracker = BodyTracker(body, Intrinsics.kinect_v1(), TrackerConfig(mode="lift"))
    front, back = body.rest_pose((0.0, 0.0, 3.0), (0.0, 1.0, 0.0, 0.0)), body.rest_pose((0.0, 0.0, 3.0))
    lying = front.copy()
    xyzw = (Rotation.from_quat(np.roll(front[3:7], -1)) * Rotation.from_euler("z", 120, degrees=True)).as_quat()
    lying[3:7] = np.roll(xyzw, 1)  # (w, x, y, z)
    assert min(root_turn_deg(front, lying), root_turn_deg(back, lying)) > REPLACED_TURN_DEG
    own = front.copy()
    own[10] = 0.2

    def winning(best: np.ndarray) -> PsoResult:
        return PsoResult(best, 1.0, np.array([1.0]), 2, np.stack([best, own]), np.array([1.0, 2.0]))

    tracker.previous, tracker.age = front, 7
    tracker.history.restart(front)
    np.testing.assert_array_equal(tracker._hold_facing(winning(back)), own)
    np.testing.assert_array_equal(tracker._hold_facing(winning(lying)), own)  # not the same challenger
    assert tracker.challenger is lying and tracker.history.poses == [front]
    tracker.reset()
    assert tracker.challenger is None and tracker.age == 0 and tracker.previous is None


@pytest.mark.slow
def test_the_best_hypotheses_search_in_sub_swarms_of_their_own(body, sequence, monkeypatch):
    """With the whole-pose swarm (offline) and ``hypotheses = 2`` a tracked frame's search gets the
    groups: the track's swarm first, then sub-swarms of round(3/16 P) particles at the end, each
    started on a pose that differs from the previous solution (the swarm's first particle) in one
    limb alone (a flip or an arm proposal); with 0, no frame's search has groups."""
    import swarmpose.tracking.body_tracker as module
    from swarmpose.tracking.search import LIMB_COLUMNS

    real, calls = module.minimise, []

    def recording(objective, start, *args, groups=None, **kwargs):
        calls.append((np.array(start), groups))
        return real(objective, start, *args, groups=groups, **kwargs)

    monkeypatch.setattr(module, "minimise", recording)
    track(body, sequence, hypotheses=0)
    assert calls and all(groups is None for _, groups in calls)
    calls.clear()
    track(body, sequence, hypotheses=2)
    grouped = [(start, groups) for start, groups in calls if groups is not None]
    assert grouped, "some tracked frame had proposals"
    limbs = [set(cols.tolist()) for cols in LIMB_COLUMNS[:4]]
    for start, groups in grouped:
        size = round(3 / 16 * len(start))
        labels = sorted(set(groups.tolist()))
        assert labels[0] == 0 and labels[1:] == list(range(1, len(labels)))
        for label in labels[1:]:
            rows = np.flatnonzero(groups == label)
            assert len(rows) == size and rows[-1] == len(start) - (label - 1) * size - 1
            changed = set(np.flatnonzero(np.abs(start[rows[0]] - start[0]) > 1e-12).tolist())
            assert changed and any(changed <= limb for limb in limbs), changed


@pytest.mark.slow
def test_the_polish_takes_the_searched_pose_further_down_and_leaves_the_arms(body, sequence):
    frame, det = next(frames_of(sequence))
    intr = Intrinsics.load(sequence / "intrinsic.json")
    plain = BodyTracker(body, intr, TrackerConfig(**SMALL, polish=0)).step(frame, det)
    polished = BodyTracker(body, intr, TrackerConfig(**SMALL, polish=40)).step(frame, det)
    arms = ~WITHOUT_ARMS
    assert np.array_equal(polished.pose[arms], plain.pose[arms])  # the same search, the arms as it left them
    assert polished.objective["E"] < plain.objective["E"], (polished.objective["E"], plain.objective["E"])
    assert np.any(polished.pose[WITHOUT_ARMS] != plain.pose[WITHOUT_ARMS])


def test_enough_of_the_torso_to_start_is_three_of_four_or_a_pair():
    from swarmpose.tracking.init_pose import torso_enough

    assert torso_enough(["left_hip", "right_hip", "left_shoulder"])
    assert torso_enough(["left_shoulder", "right_shoulder", "nose"])  # an upper body filling the frame
    assert torso_enough(["left_hip", "right_hip"])
    assert not torso_enough(["left_hip", "right_hip"], pairs=False)  # a running track assumes no upright torso
    assert not torso_enough(["left_hip", "left_shoulder", "nose", "left_ear"])
    assert not torso_enough([])
