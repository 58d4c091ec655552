"""The centred smoothing of recordings (``--smoothing centred``): the line fit, where trajectories
are cut, when results come, and a tracked run's published poses against its found ones."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import swarmpose
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_LIMITS, ANGLES, EVAL_JOINTS, POSE_DIM, ROOT_QUATERNION
from swarmpose.cli.main import main
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.pipeline.centred_smoothing import CentredSmoother, local_linear_pose, segment_starts
from swarmpose.sources.groundtruth import load_ground_truth
from swarmpose.sources.registry import open_source
from swarmpose.tracking.config import TrackerConfig
from swarmpose.tracking.result import BodyResult, FrameResult

CAMERA = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
FRAME_NS = 33_333_333
SIGMA_S = 0.05  # span 0.15 s: a frame goes out once one 5 frames (0.167 s) later has come


def _upright(x: float = 0.0, z: float = 3.0) -> np.ndarray:
    pose = np.zeros(POSE_DIM)
    pose[:3] = (x, 0.0, z)
    pose[ROOT_QUATERNION] = (0.0, 1.0, 0.0, 0.0)  # upright, facing the camera
    return pose


def _turned(pose: np.ndarray, radians: float) -> np.ndarray:
    out = pose.copy()
    q = Rotation.from_rotvec([0.0, radians, 0.0]) * Rotation.from_quat(np.roll(pose[ROOT_QUATERNION], -1))
    out[ROOT_QUATERNION] = np.roll(q.as_quat(), 1)
    return out


@pytest.fixture(scope="module")
def body():
    return load_body("builtin")


def _result(body, index: int, pose: np.ndarray | None, state: str = "tracking", body_id: int = 0,
            stamp_ns: int | None = None) -> FrameResult:
    """A frame result with one body whose joints are ``body`` posed at ``pose`` (none: lost)."""
    n = len(EVAL_JOINTS)
    if pose is None:
        bodies = (BodyResult(body_id, "lost", "", None, np.full((n, 3), np.nan), np.full((n, 2), np.nan),
                             np.zeros(n)),)
    else:
        joints3d = body.posed_points(pose[None], EVAL_JOINTS)[0]
        bodies = (BodyResult(body_id, state, "", pose, joints3d, CAMERA.project(joints3d), np.ones(n)),)
    return FrameResult(index, index * FRAME_NS if stamp_ns is None else stamp_ns, bodies)


def _smooth(body, results: list[FrameResult], sigma_s: float = SIGMA_S) -> tuple[list[FrameResult], list[int]]:
    """Every result through a smoother; also how many results each ``add`` handed on."""
    smoother = CentredSmoother(sigma_s)
    out, counts = [], []
    for r in results:
        smoother.note_bodies(r, lambda _id: body, CAMERA)
        done = smoother.add(r)
        counts.append(len(done))
        out += done
    return out + smoother.finish(), counts


def test_the_line_fit_keeps_straight_motion_to_the_ends_and_averages_noise_in_the_middle():
    offsets = (np.arange(9) - 4) / 30.0
    weights = np.exp(-0.5 * (offsets / SIGMA_S) ** 2)
    poses = np.repeat(_upright()[None], 9, axis=0)
    poses[:, 0] += 0.3 * offsets  # a straight walk, 0.3 m/s
    poses[:, 10] += 2.0 * offsets  # an angle turning at 2 rad/s
    assert np.allclose(local_linear_pose(poses, offsets, weights, 4), poses[4], atol=1e-12)
    end = slice(0, 5)  # the last frame of a trajectory: only earlier ones, no lag
    assert np.allclose(local_linear_pose(poses[end], offsets[end], weights[end], 4), poses[4], atol=1e-12)
    noisy = poses.copy()
    noisy[:, 12] += 0.1 * (-1.0) ** np.arange(9)  # jitter; balanced offsets: the weighted mean (hand: np.average)
    assert local_linear_pose(noisy, offsets, weights, 4)[12] == pytest.approx(np.average(noisy[:, 12], weights=weights))


def test_root_quaternions_of_either_sign_average_to_one_unit_rotation():
    poses = np.stack([_turned(_upright(), a) for a in (-0.1, 0.0, 0.1)])
    flipped = poses.copy()
    flipped[0, ROOT_QUATERNION] *= -1  # the same rotation
    offsets, weights = np.array([-1.0, 0.0, 1.0]) / 30, np.ones(3)
    a, b = local_linear_pose(poses, offsets, weights, 1), local_linear_pose(flipped, offsets, weights, 1)
    assert np.allclose(a, b) and np.linalg.norm(a[ROOT_QUATERNION]) == pytest.approx(1.0)
    assert np.allclose(a[ROOT_QUATERNION], poses[1, ROOT_QUATERNION], atol=1e-12)


def test_trajectories_are_cut_where_lost_restarted_or_turned_round():
    p = _upright()
    poses = [p, p, None, p, p, _turned(p, np.pi), p, _turned(p, 0.5)]
    states = ["init", "tracking", "lost", "tracking", "init", "tracking", "tracking", "tracking"]
    # lost at 2; restart at 4; half a turn at 5 (a corrected facing) and back at 6; 0.5 rad at 7 is motion
    assert segment_starts(poses, states) == [0, 0, -1, 3, 4, 5, 6, 6]
    short, tall = object(), object()  # a height locked at frame 2: the joints jump with no motion
    assert segment_starts([p] * 4, ["tracking"] * 4, [short, short, tall, tall]) == [0, 0, 2, 2]


def test_results_come_in_order_three_sigma_late_with_the_found_pose_kept(body):
    rng = np.random.default_rng(0)
    truth = [_upright(x=0.01 * i) for i in range(20)]
    for t in truth:
        t[ANGLES] = ANGLE_LIMITS.mean(axis=1)  # still angles, in the middle of their ranges
    found = [t.copy() for t in truth]
    for f in found:
        f[7:] += rng.normal(0.0, 0.05, POSE_DIM - 7)  # jitter of every angle
    results = [_result(body, i, f) for i, f in enumerate(found)]
    out, counts = _smooth(body, results)
    assert [r.index for r in out] == list(range(20))
    assert counts == [0] * 5 + [1] * 15  # 0.15 s late: frame i goes out with frame i + 5
    for r, f in zip(out, results):
        assert r.bodies[0].unfiltered is f.bodies[0]
        # the joints are the body posed at the published pose (hand: the body's own forward kinematics)
        assert np.allclose(r.bodies[0].joints3d, body.posed_points(r.bodies[0].pose[None], EVAL_JOINTS)[0], atol=1e-9)
        assert np.allclose(r.bodies[0].joints2d, CAMERA.project(r.bodies[0].joints3d))
    true_joints = body.posed_points(np.stack(truth), EVAL_JOINTS)

    def error_mm(run):
        return 1000 * np.mean([np.linalg.norm(r.bodies[0].joints3d - t, axis=1).mean()
                               for r, t in zip(run, true_joints)])

    assert error_mm(out) < 0.7 * error_mm(results), (error_mm(results), error_mm(out))


def test_a_joint_counts_by_its_confidence_in_each_frame(body):
    """A still person whose left wrist the detector lost on every other frame (0 confidence there) and
    found 0.1 m off on those: at a frame between two such, the published wrist lies at the weighted
    mean of the positions with weights Gaussian x (confidence + floor) (hand: np.average), a few mm from
    the true wrist, where the Gaussian alone aims 5 cm off."""
    from swarmpose.pipeline.centred_smoothing import CONFIDENCE_FLOOR

    wrist = EVAL_JOINTS.index("left_wrist")
    results = []
    for i in range(11):
        r = _result(body, i, _upright())
        b = r.bodies[0]
        joints3d, confidence = b.joints3d.copy(), b.confidence.copy()
        if i % 2:
            joints3d[wrist, 0] += 0.1
            confidence[wrist] = 0.0
        results.append(replace(r, bodies=(replace(b, joints3d=joints3d, confidence=confidence),)))
    out, _ = _smooth(body, results)
    times = (np.arange(11) - 4) / 30.0
    near = np.flatnonzero(np.abs(times) <= 3 * SIGMA_S)
    gauss = np.exp(-0.5 * (times[near] / SIGMA_S) ** 2)
    x = np.array([results[i].bodies[0].joints3d[wrist, 0] for i in near])
    weighted = np.average(x, weights=gauss * (np.where(near % 2, 0.0, 1.0) + CONFIDENCE_FLOOR))
    published = out[4].bodies[0].joints3d[wrist, 0]
    true = results[4].bodies[0].joints3d[wrist, 0]
    assert abs(weighted - true) < 0.005 and abs(published - true) < 0.003  # (the Gaussian alone: 6.6 mm)
    assert abs(np.average(x, weights=gauss) - results[4].bodies[0].joints3d[wrist, 0]) > 0.03


def test_nothing_is_averaged_across_a_lost_frame_or_a_corrected_facing(body):
    poses = [_upright(x=0.0)] * 6 + [None] + [_upright(x=0.5)] * 6 + [_turned(_upright(x=0.5), np.pi)] * 6
    results = [_result(body, i, p, "lost" if p is None else "tracking") for i, p in enumerate(poses)]
    out, _ = _smooth(body, results)
    for r, p in zip(out, poses):
        if p is None:
            assert r.bodies[0].state == "lost" and r.bodies[0].pose is None
        else:
            assert np.allclose(r.bodies[0].pose, p, atol=1e-8)  # (a bound nudges an angle by 1e-10)


def test_nothing_is_averaged_across_a_change_of_body(body):
    scaled = load_body("builtin", "height=1.9")  # another body object: a height locked at frame 6
    poses = [_upright(x=0.0)] * 6 + [_upright(x=0.2)] * 6
    results = [_result(body if i < 6 else scaled, i, p) for i, p in enumerate(poses)]
    smoother, out = CentredSmoother(SIGMA_S), []
    for r in results:
        smoother.note_bodies(r, lambda _id, i=r.index: body if i < 6 else scaled, CAMERA)
        out += smoother.add(r)
    out += smoother.finish()
    assert all(np.allclose(r.bodies[0].pose, p, atol=1e-8) for r, p in zip(out, poses))


def test_timestamps_that_do_not_advance_count_as_thirty_frames_a_second(body):
    rng = np.random.default_rng(1)
    poses = [_upright(x=rng.normal(0, 0.02)) for _ in range(12)]
    stamped, _ = _smooth(body, [_result(body, i, p) for i, p in enumerate(poses)])
    unstamped, _ = _smooth(body, [_result(body, i, p, stamp_ns=0) for i, p in enumerate(poses)])
    assert all(np.allclose(a.bodies[0].pose, b.bodies[0].pose) for a, b in zip(stamped, unstamped))


def test_a_body_with_no_known_body_model_and_a_failed_run_pass_unchanged(body):
    smoother = CentredSmoother(SIGMA_S)
    results = [_result(body, i, _upright(x=0.01 * (-1) ** i)) for i in range(8)]
    out = []
    for r in results:  # no note_bodies: the poses cannot be posed again, so they are left as found
        out += smoother.add(r)
    out += smoother.finish()
    assert all(a is b for a, b in zip(out, results)) and len(out) == 8
    smoother = CentredSmoother(SIGMA_S)
    for r in results[:3]:
        smoother.note_bodies(r, lambda _id: body, CAMERA)
        assert smoother.add(r) == []
    assert smoother.release() == results[:3]  # as found


def test_a_sigma_of_zero_is_refused():
    with pytest.raises(ValueError, match="above 0"):
        CentredSmoother(0.0)


@pytest.mark.slow
def test_a_tracked_run_publishes_the_smoothed_poses_of_the_same_track(side_wave, body):
    settings = {"particles": 16, "generations": 12, "max_people": 1, "auto_height": False}
    found = list(swarmpose.track(f"folder:{side_wave}", detector="simulated", **settings))
    smoothed = list(swarmpose.track(f"folder:{side_wave}", detector="simulated", smoothing="centred", **settings))
    assert [r.index for r in smoothed] == list(range(20))
    assert all(r.timings_ms["smoothing"] > 0 for r in smoothed)  # its time, counted in a run's frames/s
    # the search is the same: each published body keeps the unsmoothed run's fit as its found one
    assert all(np.array_equal(s.bodies[0].found.pose, f.bodies[0].pose) for s, f in zip(smoothed, found))
    # and what is published is the smoother's output over that run's results (the module's own unit tests
    # check the smoother against hand computation)
    tracking_body = body if len(body.triangles) <= TrackerConfig().triangles else body.tracking_lod(
        TrackerConfig().triangles)
    by_hand, _ = _smooth(tracking_body, [replace(r, bodies=(r.bodies[0],)) for r in found])
    assert all(np.allclose(s.bodies[0].pose, h.bodies[0].pose, atol=1e-9) for s, h in zip(smoothed, by_hand))
    gt = load_ground_truth(side_wave)

    def error_mm(run):
        return np.mean([1000 * np.linalg.norm(r.bodies[0].joints3d - gt.joints3d[gt.row(r.index)], axis=1).mean()
                        for r in run])

    assert error_mm(smoothed) <= error_mm(found) + 1.0, (error_mm(found), error_mm(smoothed))


def test_live_commands_refuse_it_and_name_what_to_run(wave_sequence, tmp_path, capsys):
    assert main(["replay", str(wave_sequence), "--out", str(tmp_path), "--smoothing", "centred", "-q"]) == 2
    assert "swarmpose track" in capsys.readouterr().err
    source = open_source(f"folder:{wave_sequence}")
    with swarmpose.Tracker("builtin", "simulated", source=source, smoothing="centred") as tracker:
        with pytest.raises(ConfigError, match="swarmpose.track"):
            tracker.track_frame(next(iter(source)))
    source.close()
    assert TrackerConfig(backward=5, smoothing="centred").centred_sigma_s == SIGMA_S  # runs after the backward pass


@pytest.mark.slow
def test_personalize_collects_its_samples_with_the_offline_settings(side_wave):
    """``personalize --smoothing centred`` (and ``--backward N``) apply to the poses its fit starts
    from: the samples' poses are those a smoothed run of the same start body publishes."""
    from swarmpose.body.shape_space import shape_space_for
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.pipeline.personalise_run import collect_samples

    space = shape_space_for("builtin", None, TrackerConfig().triangles)
    budget = {"particles": 16, "generations": 12}
    poses = {}
    for smoothing in ("off", "centred"):
        config = ServiceConfig(source=f"folder:{side_wave}", detector="simulated", body="builtin",
                               tracker=TrackerConfig(smoothing=smoothing, **budget))
        samples, _, read = collect_samples(config, space, 20, show_progress=False)
        assert read == 20 and len(samples) == 20
        poses[smoothing] = np.stack([s.pose for s in samples])
    published = np.stack([r.bodies[0].pose for r in swarmpose.track(
        f"folder:{side_wave}", body=space.tracking_body(space.start), detector="simulated", smoothing="centred",
        **budget)])
    assert np.allclose(poses["centred"], published, atol=1e-9)
    assert not np.allclose(poses["centred"], poses["off"])


def test_the_lift_mode_has_no_pose_to_smooth_and_refuses_it():
    with pytest.raises(ConfigError, match="lift mode fits no body"):
        TrackerConfig(mode="lift", smoothing="centred")


@pytest.mark.slow
def test_after_the_backward_pass_each_frame_is_fitted_with_the_body_it_was_refit_with(tmp_path):
    """A 1.9 m person: the automatic height locks a body scaled to them in the middle of the window, and
    the backward pass refits the whole window with it, so every published pose, smoothed, is that
    body's (its joints are the scaled body posed at the published pose)."""
    from swarmpose.pipeline.run import results

    assert main(["synth", "--shape", "height=1.9", "--motion", "builtin:wave", "--frames", "20", "--camera-yaw", "90",
                 "--out", str(tmp_path), "--quiet"]) == 0
    source = open_source(f"folder:{tmp_path}")
    with swarmpose.Tracker("builtin", "simulated", source=source, backward=20, smoothing="centred",
                           particles=16, generations=12, max_people=1) as tracker:
        run = list(results(source, tracker.pipeline))
        final = tracker.pipeline.body_of(0)
        start = tracker.body
    source.close()
    assert [r.index for r in run] == list(range(20))
    assert np.ptp(final.vertices[:, 1]) > 1.05 * np.ptp(start.vertices[:, 1])  # locked, scaled to the person
    for r in run:
        b = r.bodies[0]
        assert np.allclose(b.joints3d, final.posed_points(b.pose[None], EVAL_JOINTS)[0], atol=1e-6), r.index


@pytest.mark.slow
def test_with_several_people_each_id_is_smoothed_on_its_own_track(two_people):
    folder = two_people
    settings = {"particles": 16, "generations": 12, "max_people": 3, "auto_height": False}
    found = list(swarmpose.track(f"folder:{folder}", detector="simulated", **settings))
    smoothed = list(swarmpose.track(f"folder:{folder}", detector="simulated", smoothing="centred", **settings))
    assert [[b.id for b in r.bodies] for r in smoothed] == [[b.id for b in r.bodies] for r in found]
    pairs = [(s, f) for rs, rf in zip(smoothed, found) for s, f in zip(rs.bodies, rf.bodies) if f.pose is not None]
    assert pairs and all(np.array_equal(s.found.pose, f.pose) for s, f in pairs)
    assert sum(s.unfiltered is not None for s, _ in pairs) >= len(pairs) - 2  # each person smoothed
    for s, f in pairs:  # a person's smoothing moves their joints by steps' worth, never to the other person
        assert np.linalg.norm(s.joints3d - f.joints3d, axis=1).max() < 0.3
