"""The replay files: poses.jsonl, poses.csv, the BVH files (one per body id) and open_recording.

Oracles: JSON and CSV are read back with the stdlib readers and compared with the messages;
the BVH is read back with the third-party ``bvhio`` and with ``swarmpose.motion.bvh`` and its
root channels and joint positions compared with the messages' poses and the bone heads of
``forward_kinematics`` turned Y up (x 100 cm, y and z negated). Which rows each id's file
must hold is worked out by hand from a scripted scene of several people.
"""

from __future__ import annotations

import csv
import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import MAKEHUMAN, needs_assets
from scipy.spatial.transform import Rotation

from swarmpose.body.joint_set import SKELETON_NAMES
from swarmpose.body.kinematics import forward_kinematics, matrix_to_quaternion
from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import ANGLE_LIMITS, EVAL_JOINTS
from swarmpose.core.errors import OutputError
from swarmpose.messages import POSE_NAMES, body_message, frame_message, validate
from swarmpose.motion.builtin import builtin_motion
from swarmpose.motion.bvh import read_bvh
from swarmpose.publish.bvh_file import UPRIGHT, BvhSink, PerIdBvhSink
from swarmpose.publish.files import CsvSink, JsonlSink, open_recording
from swarmpose.publish.overlay import OverlaySink
from swarmpose.publish.ros_bag import RosBagSink
from swarmpose.sim.synth import SynthConfig, place_camera

TO_BVH = np.array([100.0, -100.0, -100.0])  # camera frame m -> BVH world cm (Y up)


def entry(seed: int, pose: np.ndarray | None = None, state: str = "tracking", reason: str = "",
          unknown: tuple[int, ...] = (), body_id: int = 0) -> dict:
    """One body of a frame message (``body_message``) with random joints; joints listed in
    ``unknown`` are NaN (null in the message)."""
    rng = np.random.default_rng(seed)
    joints3d = rng.uniform(-1, 1, (14, 3)) + [0, 0, 3]
    joints2d = rng.uniform(0, 640, (14, 2))
    joints3d[list(unknown)] = np.nan
    joints2d[list(unknown)] = np.nan
    skeleton = None
    if pose is not None:  # the full set: random positions, pixels and unit quaternions
        q = rng.normal(size=(len(SKELETON_NAMES), 4))
        skeleton = (rng.uniform(-1, 1, (len(SKELETON_NAMES), 3)) + [0, 0, 3],
                    rng.uniform(0, 640, (len(SKELETON_NAMES), 2)), q / np.linalg.norm(q, axis=1, keepdims=True))
    return body_message(body_id, state, reason, None if pose is None else np.asarray(pose, dtype=float),
                        joints3d, joints2d, rng.uniform(0, 1, 14), {"E": float(rng.uniform(0, 5)), "E_D": 1.0},
                        skeleton=skeleton)


def message(index: int, bodies: list[dict], reason: str = "") -> dict:
    t0 = 1_700_000_000_000_000_000 + index * 33_000_000
    return frame_message("cam0", index, index * 33_333_333, t0, t0 + 12_345_678, bodies, reason)


def sample_messages() -> list[dict]:
    rng = np.random.default_rng(7)
    pose = np.concatenate([[0.1, -0.2, 3.0, 0.0, 1.0, 0.0, 0.0], rng.uniform(-0.2, 0.2, 29)])
    return [
        message(0, [entry(1, pose)]),
        message(1, [], reason="skipped: color/000001.png missing"),
        message(2, [entry(2, pose, unknown=(3, 7)), entry(3, None, "init", "no joints", body_id=1)]),
    ]


# ---------------------------------------------------------------------------- JSONL
def test_jsonl_lines_are_the_messages_and_on_disk_at_once(tmp_path):
    path = tmp_path / "poses.jsonl"
    messages = sample_messages()
    sink = JsonlSink(path)
    for k, msg in enumerate(messages):
        sink.frame(msg, None)
        lines = path.read_text("utf-8").splitlines()  # read back before close
        assert len(lines) == k + 1
        assert json.loads(lines[-1]) == msg
    sink.status({"schema": "swarmpose.status"})  # not recorded
    sink.close()
    sink.close()  # idempotent
    lines = path.read_text("utf-8").splitlines()
    assert [json.loads(line) for line in lines] == messages
    for line in lines:
        validate(json.loads(line))
        assert line == json.dumps(json.loads(line), separators=(",", ":"))  # compact, no spaces outside strings
    with pytest.raises(OutputError, match="closed"):
        sink.frame(messages[0], None)


# ---------------------------------------------------------------------------- CSV
def expected_header() -> list[str]:
    joints = [f"{j}_{f}" for j in EVAL_JOINTS for f in ("x", "y", "z", "u", "v", "confidence")]
    extra = [f"{j}_{f}" for j in SKELETON_NAMES if j not in EVAL_JOINTS
             for f in ("x", "y", "z", "u", "v", "confidence")]
    quaternions = [f"{j}_{f}" for j in SKELETON_NAMES for f in ("qx", "qy", "qz", "qw")]
    return ["frame", "capture_ns", "received_ns", "publish_ns", "latency_ms", "coordinates", "body_id", "state",
            "reason",
            *joints, *POSE_NAMES, "objective", *extra, *quaternions]


def cell(value) -> str:
    """How a message value must appear in the CSV: empty when unknown, else a number."""
    return "" if value is None else value


def test_csv_rows_hold_the_message_values(tmp_path):
    path = tmp_path / "poses.csv"
    messages = sample_messages()
    sink = CsvSink(path)
    sink.frame(messages[0], None)
    with open(path, newline="", encoding="utf-8") as f:  # on disk before close
        assert len(list(csv.reader(f))) == 2
    for msg in messages[1:]:
        sink.frame(msg, None)
    sink.close()
    sink.close()
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == expected_header()
        rows = list(reader)
    assert [int(r["frame"]) for r in rows] == [0, 1, 2, 2]  # one row per frame and body
    assert len(expected_header()) == 9 + 14 * 6 + 36 + 1 + 14 * 6 + 28 * 4  # earlier columns first, in place

    # frame 1: no body -> one row, empty body cells, the frame's reason
    empty = rows[1]
    assert empty["reason"] == messages[1]["reason"]
    assert empty["body_id"] == empty["state"] == empty["objective"] == ""
    assert all(empty[c] == "" for c in expected_header()[9:])
    assert int(empty["publish_ns"]) == messages[1]["publish_ns"]

    for row, (msg, body) in zip([rows[0], rows[2], rows[3]],
                                [(messages[0], messages[0]["bodies"][0]), (messages[2], messages[2]["bodies"][0]),
                                 (messages[2], messages[2]["bodies"][1])]):
        for key in ("frame", "capture_ns", "received_ns", "publish_ns"):
            assert int(row[key]) == msg[key]
        assert float(row["latency_ms"]) == msg["latency_ms"]
        assert row["coordinates"] == msg["coordinates"] == "camera"
        assert int(row["body_id"]) == body["id"] and row["state"] == body["state"]
        for name in SKELETON_NAMES:
            joint = body["joints"][name]
            got = [row[f"{name}_{f}"] for f in ("qx", "qy", "qz", "qw")]
            assert [float(g) if g else None for g in got] == (joint["orientation_xyzw"] or [None] * 4)
            got = [row[f"{name}_{f}"] for f in ("x", "y", "z", "u", "v")]
            want = (joint["position_m"] or [None] * 3) + (joint["pixel"] or [None] * 2)
            assert [float(g) if g else None for g in got] == want
            assert float(row[f"{name}_confidence"]) == joint["confidence"]
        pose = [row[n] for n in POSE_NAMES]
        assert [float(p) if p else None for p in pose] == (body["pose"] or [None] * 36)
        assert float(row["objective"]) == body["objective"]["E"]
    # the unknown joints of body 0 of frame 2 are empty cells
    assert rows[2][f"{EVAL_JOINTS[3]}_x"] == "" and rows[2][f"{EVAL_JOINTS[7]}_u"] == ""
    assert rows[3]["reason"] == "no joints" and rows[3]["tx"] == ""


# ---------------------------------------------------------------------------- BVH
def bvhio_positions(path, names: tuple[str, ...], frames: int) -> np.ndarray:
    """World positions (N, B, 3) of the named joints per frame, as bvhio computes them."""
    import bvhio

    root = bvhio.readAsHierarchy(str(path))
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    out = np.empty((frames, len(names), 3))
    for f in range(frames):
        root.loadPose(f)
        out[f] = [list(joints[n].PositionWorld) for n in names]
    return out


def own_positions(path, names: tuple[str, ...]) -> np.ndarray:
    clip = read_bvh(path)
    _, pos = clip.global_transforms()
    return pos[:, [clip.joint_index(n) for n in names]]


def write_and_check(tmp_path, body, poses: np.ndarray, fps: float = 30.0) -> None:
    """Write ``poses`` (with frames lacking a pose in between) and compare both readers with FK."""
    path = tmp_path / "poses.bvh"
    _, heads = forward_kinematics(body.rig, poses)
    expected = heads * TO_BVH
    sink = BvhSink(path, body, fps=fps)
    want = []
    for k, h in enumerate(poses):
        sink.frame(message(k, [entry(k, h)]), None)
        want.append(expected[k])
        if k % 4 == 1:  # a frame with no body, then one whose body has no pose: both repeat the row
            sink.frame(message(k, [], "no person"), None)
            sink.frame(message(k, [entry(k, None, "lost", "lost")]), None)
            want += [expected[k], expected[k]]
        if k == 2:  # the file is complete while being written
            assert own_positions(path, body.bone_names).shape[0] == len(want)
    sink.close()
    sink.close()
    want = np.array(want)
    clip = read_bvh(path)
    assert len(clip) == len(want)
    assert clip.frame_time == pytest.approx(1.0 / fps, rel=1e-6)
    assert set(clip.joint_names) == set(body.bone_names)
    for b, parent in enumerate(body.bone_parents):  # the hierarchy is the rig's
        if parent >= 0:
            assert clip.joint_names[clip.parents[clip.joint_index(body.bone_names[b])]] == body.bone_names[parent]
    np.testing.assert_allclose(own_positions(path, body.bone_names), want, atol=1e-3)
    np.testing.assert_allclose(bvhio_positions(path, body.bone_names, len(want)), want, atol=1e-3)
    rows = path.read_text("ascii").splitlines()[-len(want):]
    assert rows[1] == rows[2] == rows[3]  # the repeated rows are the same text


@pytest.fixture(scope="module")
def builtin_body():
    return load_body("builtin", "default")


def camera_poses(body, name: str, frames: int) -> np.ndarray:
    motion = builtin_motion(name, frames, 30.0)
    return place_camera(body, motion, SynthConfig(frames=frames, fps=30.0)).poses


def test_bvh_of_a_walk_matches_forward_kinematics(tmp_path, builtin_body):
    write_and_check(tmp_path, builtin_body, camera_poses(builtin_body, "walk", 12))


def test_bvh_of_random_poses_with_gimbal_lock(tmp_path, builtin_body):
    rng = np.random.default_rng(3)
    n = 8
    poses = np.zeros((n, 36))
    poses[:, 0:3] = rng.uniform(-1, 1, (n, 3)) + [0, 0, 3]
    poses[:, 3:7] = rng.normal(size=(n, 4))
    poses[:, 7:] = rng.uniform(ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1], (n, 29))
    # root at the ZXY singularity in the BVH world: flip (x 180) then 90 degrees about x
    bvh_root = Rotation.from_euler("ZXY", [30, 90, -20], degrees=True).as_matrix()
    poses[0, 3:7] = matrix_to_quaternion(np.diag([1.0, -1.0, -1.0]) @ bvh_root)
    write_and_check(tmp_path, builtin_body, poses, fps=25.0)


@pytest.mark.parametrize("spec, first, then", [
    ("builtin", "default", "height=1.9"),
    pytest.param(f"makehuman:{MAKEHUMAN}", "male", "female-short", marks=needs_assets),  # rest frames differ
])
def test_bvh_rewritten_for_a_new_body_animates_it_from_the_first_frame(tmp_path, spec, first, then):
    """A BVH file whose body may change (--personalize) and then changes: the file holds the
    new body's skeleton and every row, those written before the change too, places the new
    rig's joints where the numpy FK of the same poses on it does (both readers); a frame
    without a pose before the change repeats the new rig's row; a rig with other bones is
    refused. (MakeHuman shapes differ in their bones' rest frames, so the rows written before
    the change must be recomputed, not only the header.)"""
    start, tall = load_body(spec, first), load_body(spec, then)
    poses = camera_poses(start, "walk", 9)
    path = tmp_path / "poses.bvh"
    sink = BvhSink(path, start, may_change=True)
    want = []
    _, on_tall = forward_kinematics(tall.rig, poses)
    for k, h in enumerate(poses):
        if k == 5:
            assert sink.use_body(tall) and not sink.use_body(tall)  # the second time changes nothing
        sink.frame(message(k, [entry(k, h)]), None)
        want.append(on_tall[k] * TO_BVH)
        if k == 2:  # no pose: the row repeats the last one
            sink.frame(message(k, [], "no person"), None)
            want.append(on_tall[k] * TO_BVH)
    with pytest.raises(OutputError, match="other bones"):
        sink.use_body(_renamed_rig(start))
    sink.close()
    want = np.array(want)
    clip = read_bvh(path)
    assert len(clip) == len(want) == sink.frames
    for b, parent in enumerate(tall.rig.parents):  # the offsets are the tall rig's bones
        if parent >= 0:
            np.testing.assert_allclose(clip.offsets[clip.joint_index(tall.bone_names[b])],
                                       100.0 * (tall.rig.heads[b] - tall.rig.heads[parent]), atol=1e-4)
    np.testing.assert_allclose(own_positions(path, tall.bone_names), want, atol=1e-3)
    np.testing.assert_allclose(bvhio_positions(path, tall.bone_names, len(want)), want, atol=1e-3)
    assert not path.with_name("poses.bvh.tmp").exists()


@needs_assets
def test_a_bvh_whose_body_changes_twice_animates_the_last_body_throughout(tmp_path):
    """--personalize gives a new person the start body back and fits again: after a second
    change every row, those before the first change too, is recomputed on the last body's rig
    (MakeHuman shapes differ in their rest frames, so rows left on an earlier rig would move)."""
    male, short = load_body(f"makehuman:{MAKEHUMAN}", "male"), load_body(f"makehuman:{MAKEHUMAN}", "female-short")
    poses = camera_poses(male, "walk", 6)
    path = tmp_path / "poses.bvh"
    sink = BvhSink(path, male, may_change=True)
    for k, h in enumerate(poses):
        if k == 2:
            assert sink.use_body(short)
        if k == 4:
            assert sink.use_body(male)
        sink.frame(message(k, [entry(k, h)]), None)
    sink.close()
    _, on_male = forward_kinematics(male.rig, poses)
    np.testing.assert_allclose(own_positions(path, male.bone_names), on_male * TO_BVH, atol=1e-3)


def test_a_failed_bvh_rewrite_leaves_the_file_and_the_sink_as_they_were(tmp_path, builtin_body):
    """The temporary file cannot be written (a folder in its way): use_body raises OutputError,
    the file, its skeleton and the sink's body are unchanged, rows go on; once the way is clear
    the rewrite succeeds."""
    tall = load_body("builtin", "height=1.9")
    poses = camera_poses(builtin_body, "walk", 4)
    path = tmp_path / "poses.bvh"
    sink = BvhSink(path, builtin_body, may_change=True)
    sink.frame(message(0, [entry(0, poses[0])]), None)
    before = path.read_bytes()
    blocker = tmp_path / "poses.bvh.tmp"
    blocker.mkdir()
    with pytest.raises(OutputError, match="poses.bvh"):
        sink.use_body(tall)
    assert path.read_bytes() == before and sink.body is builtin_body
    sink.frame(message(1, [entry(1, poses[1])]), None)
    blocker.rmdir()
    assert sink.use_body(tall)
    sink.frame(message(2, [entry(2, poses[2])]), None)
    sink.close()
    _, on_tall = forward_kinematics(tall.rig, poses[:3])
    np.testing.assert_allclose(own_positions(path, tall.bone_names), on_tall * TO_BVH, atol=1e-3)
    assert not blocker.exists()


def test_bvh_rows_without_a_pose_do_not_use_up_the_kept_poses(tmp_path, builtin_body, monkeypatch, caplog):
    """Only rows with a pose count towards KEPT_POSES (nobody in view for a long time before the
    person comes does not use them up); rows beyond it keep their old values, with a warning."""
    import swarmpose.publish.bvh_file as bvh_file

    monkeypatch.setattr(bvh_file, "KEPT_POSES", 2)
    tall = load_body("builtin", "height=1.9")
    poses = camera_poses(builtin_body, "walk", 3)
    path = tmp_path / "poses.bvh"
    sink = BvhSink(path, builtin_body, may_change=True)
    for k in range(5):
        sink.frame(message(k, [], "no person"), None)
    for k, h in enumerate(poses):
        sink.frame(message(5 + k, [entry(k, h)]), None)
    sink.use_body(tall)
    sink.close()
    assert "keep their angles on the old skeleton" in caplog.text
    got = own_positions(path, tall.bone_names)
    _, on_tall = forward_kinematics(tall.rig, poses)
    np.testing.assert_allclose(got[5:7], on_tall[:2] * TO_BVH, atol=1e-3)  # the kept poses, recomputed
    np.testing.assert_allclose(got[:5, 0], np.repeat(got[:1, 0], 5, axis=0))  # the rest pose, five times


def _renamed_rig(body) -> SimpleNamespace:
    """What use_body reads of a body whose last bone hangs from the root: another skeleton of
    as many bones."""
    parents = body.rig.parents.copy()
    parents[-1] = 0
    return SimpleNamespace(name="re-parented", rig=SimpleNamespace(parents=parents, heads=body.rig.heads + 0.01))


def test_per_id_bvh_files_follow_each_ids_current_body(tmp_path, builtin_body):
    """PerIdBvhSink with body_of: each id's file starts with that id's body and is rewritten
    when it changes; without body_of nothing is kept to rewrite."""
    tall = load_body("builtin", "height=1.9")
    current = {0: builtin_body, 3: tall}
    sink = PerIdBvhSink(tmp_path, builtin_body, body_of=current.get)
    pose = camera_poses(builtin_body, "walk", 1)[0]
    sink.frame(message(0, [entry(0, pose), entry(1, pose, body_id=3)]), None)
    current[0] = tall
    sink.frame(message(1, [entry(2, pose), entry(3, pose, body_id=3)]), None)
    sink.close()
    _, heads = forward_kinematics(tall.rig, pose[None])
    for name in ("poses.bvh", "poses_id3.bvh"):
        np.testing.assert_allclose(own_positions(tmp_path / name, tall.bone_names),
                                   np.repeat(heads * TO_BVH, 2, axis=0), atol=1e-3)
    (tmp_path / "plain").mkdir()
    plain = PerIdBvhSink(tmp_path / "plain", builtin_body)
    assert plain.sinks[0]._poses is None
    plain.close()


def test_bvh_rest_pose_before_any_pose_stands_upright(tmp_path, builtin_body):
    path = tmp_path / "poses.bvh"
    sink = BvhSink(path, builtin_body)
    sink.frame(message(0, [], "no person yet"), None)
    sink.close()
    pos = own_positions(path, builtin_body.bone_names)[0]
    heads = builtin_body.bone_heads * 100.0  # body frame is Y up, metres
    np.testing.assert_allclose(pos, heads - heads[0], atol=1e-4)
    head, pelvis = builtin_body.bone_names.index("head"), 0
    assert pos[head, 1] > pos[pelvis, 1] + 40  # upright, cm


@needs_assets
def test_bvh_of_the_makehuman_body(tmp_path):
    body = load_body(f"makehuman:{MAKEHUMAN}", "male")
    write_and_check(tmp_path, body, camera_poses(body, "jumping_jacks", 6))


# ---------------------------------------------------------------------------- several people
SCENE: tuple[tuple[tuple[int, bool], ...], ...] = (
    ((0, True),),
    ((0, True), (1, False)),  # id 1 appears without a pose yet
    ((0, True), (1, True)),
    ((1, True),),  # id 0 absent
    (),  # nobody
    ((0, False), (1, True), (4, True)),  # id 0 lost; id 4 (a refound person's new id) appears
    ((0, True), (4, True)),  # id 1 absent
    ((4, True), (0, True)),  # the list in another order
)
"""Per frame message: the (id, has a pose) of each body it holds."""


def scene_pose(poses: np.ndarray, body_id: int, k: int) -> np.ndarray:
    """Pose (36,) of id ``body_id`` on frame ``k``: a walk at its own phase, 0.9 m beside the others."""
    h = poses[(k + 3 * body_id) % len(poses)].copy()
    h[0] += 0.9 * (body_id - 1)
    return h


def scene_messages(poses: np.ndarray) -> list[dict]:
    return [message(k, [entry(10 * k + i, scene_pose(poses, i, k) if has_pose else None,
                              "tracking" if has_pose else "init", "" if has_pose else "no joints yet", body_id=i)
                        for i, has_pose in bodies], "" if bodies else "no person")
            for k, bodies in enumerate(SCENE)]


def expected_rows(body, poses: np.ndarray, body_id: int) -> tuple[int, np.ndarray]:
    """First frame and poses (N, 36) of the rows of id ``body_id``'s file, by hand from SCENE:
    from the frame the id first appears (0 for id 0), the last pose it had (rest, upright, at
    the origin before any)."""
    first = 0 if body_id == 0 else next(k for k, bodies in enumerate(SCENE) if body_id in dict(bodies))
    last = body.rest_pose(quaternion=UPRIGHT)
    rows = []
    for k in range(first, len(SCENE)):
        if dict(SCENE[k]).get(body_id):
            last = scene_pose(poses, body_id, k)
        rows.append(last)
    return first, np.array(rows)


def test_several_people_get_one_bvh_per_id(tmp_path, builtin_body):
    poses = camera_poses(builtin_body, "walk", 12)
    out = tmp_path / "replay"
    sinks = open_recording(out, builtin_body, fps=20.0, overlay=False, ros_bag=False)
    assert [type(s) for s in sinks] == [JsonlSink, CsvSink, PerIdBvhSink]
    bvh = sinks[2]
    names = {0: "poses.bvh", 1: "poses_id1.bvh", 4: "poses_id4.bvh"}
    firsts = {i: expected_rows(builtin_body, poses, i)[0] for i in names}
    for k, msg in enumerate(scene_messages(poses)):
        for sink in sinks:
            sink.frame(msg, None)
        for i, name in names.items():  # created when the id first appears, complete after every frame
            assert (out / name).exists() == (k >= firsts[i])
            if k >= firsts[i]:
                assert len(read_bvh(out / name)) == k + 1 - firsts[i]
    assert bvh.path == out / "poses.bvh" and bvh.paths == [out / names[i] for i in (0, 1, 4)]
    for sink in sinks:
        sink.close()
    bvh.close()  # idempotent
    assert sorted(p.name for p in out.glob("*.bvh")) == sorted(names.values())
    for i, name in names.items():
        first, rows = expected_rows(builtin_body, poses, i)
        clip = read_bvh(out / name)
        assert len(clip) == len(SCENE) - first
        assert clip.frame_time == pytest.approx(1 / 20.0)
        np.testing.assert_allclose(clip.root_positions, rows[:, :3] * TO_BVH, atol=1e-4)  # the root channels
        _, heads = forward_kinematics(builtin_body.rig, rows)
        np.testing.assert_allclose(own_positions(out / name, builtin_body.bone_names), heads * TO_BVH, atol=1e-3)
    with pytest.raises(OutputError, match="closed"):
        bvh.frame(scene_messages(poses)[0], None)


def test_several_people_give_one_csv_row_each(tmp_path, builtin_body):
    poses = camera_poses(builtin_body, "walk", 12)
    messages = scene_messages(poses)
    sink = CsvSink(tmp_path / "poses.csv")
    for msg in messages:
        sink.frame(msg, None)
    sink.close()
    with open(tmp_path / "poses.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    want = [(k, i, has_pose) for k, bodies in enumerate(SCENE) for i, has_pose in bodies or ((None, False),)]
    assert [(int(r["frame"]), int(r["body_id"]) if r["body_id"] else None) for r in rows] == [w[:2] for w in want]
    for row, (k, i, has_pose) in zip(rows, want):
        if has_pose:
            np.testing.assert_allclose([float(row[n]) for n in POSE_NAMES], scene_pose(poses, i, k), atol=1e-6)
            assert row["state"] == "tracking"
        else:
            assert row["tx"] == "" and row["reason"] in ("no joints yet", "no person")


def test_bad_body_ids_are_refused(tmp_path, builtin_body):
    sink = PerIdBvhSink(tmp_path, builtin_body)
    for bad in (-1, "2", None, True):
        with pytest.raises(OutputError, match=r"frame 3: body id .* is not an integer >= 0"):
            sink.frame(message(3, [entry(0), {**entry(1), "id": bad}]), None)
    sink.close()
    assert [p.name for p in tmp_path.iterdir()] == ["poses.bvh"]
    with pytest.raises(OutputError, match="body id -2"):
        BvhSink(tmp_path / "other.bvh", builtin_body, body_id=-2)
    assert not (tmp_path / "other.bvh").exists()


# ---------------------------------------------------------------------------- folder and errors
def test_open_recording_creates_the_files(tmp_path, builtin_body):
    out = tmp_path / "run" / "replay"
    sinks = open_recording(out, builtin_body, fps=15.0)
    assert [type(s) for s in sinks] == [JsonlSink, CsvSink, PerIdBvhSink, OverlaySink, RosBagSink]
    assert [s.path.name for s in sinks] == ["poses.jsonl", "poses.csv", "poses.bvh", "overlay.mp4", "poses_ros2"]
    for sink in sinks:
        sink.frame(sample_messages()[0], None)
        sink.close()
    assert {p.name for p in out.iterdir()} == {"poses.jsonl", "poses.csv", "poses.bvh", "poses_ros2"}  # no video
    assert read_bvh(out / "poses.bvh").frame_time == pytest.approx(1 / 15.0)
    assert len(open_recording(tmp_path / "other", builtin_body, overlay=False, ros_bag=False)) == 3


def test_unwritable_paths_raise_output_error(tmp_path, builtin_body):
    blocker = tmp_path / "a_file"
    blocker.write_text("in the way")
    target = blocker / "poses"
    for make in (lambda: JsonlSink(target / "poses.jsonl"), lambda: CsvSink(target / "poses.csv"),
                 lambda: BvhSink(target / "poses.bvh", builtin_body), lambda: OverlaySink(target / "overlay.mp4")):
        with pytest.raises(OutputError, match=re.escape(str(target))):
            make()
    with pytest.raises(OutputError, match=re.escape(str(blocker))):
        open_recording(blocker, builtin_body)
    with pytest.raises(OutputError, match=re.escape(str(target))):
        open_recording(target, builtin_body)


# ---------------------------------------------------------------------------- world frame
def test_bvh_and_csv_follow_the_messages_world_frame(tmp_path, builtin_body):
    """A message carrying ``camera_to_world`` puts the BVH in that world (oracle: forward
    kinematics moved by the transform); the same poses sent in world coordinates give the
    same rows; before any pose, the rest pose stands on the floor at the origin."""
    from swarmpose.core.world import normal_of_angles, transform_points, transform_poses, world_from_floor

    poses = camera_poses(builtin_body, "walk", 6)
    t = world_from_floor(normal_of_angles(12.0, 2.0), 1.3, poses[0, 0:3])
    camera_file, world_file = tmp_path / "camera.bvh", tmp_path / "world.bvh"
    as_camera, as_world = BvhSink(camera_file, builtin_body), BvhSink(world_file, builtin_body)
    csv_sink = CsvSink(tmp_path / "poses.csv")
    for k, h in enumerate(poses):
        plain = message(k, [entry(k, h)])
        if k == 0:  # no pose yet, but the world known: the rest pose on the floor
            as_camera.frame({**plain, "bodies": [], "camera_to_world": t.tolist()}, None)
        as_camera.frame({**plain, "camera_to_world": t.tolist()}, None)
        world = {**message(k, [entry(k, transform_poses(t, h))]), "coordinates": "world",
                 "camera_to_world": t.tolist()}
        validate(world)
        as_world.frame(world, None)
        csv_sink.frame(world, None)
    for sink in (as_camera, as_world, csv_sink):
        sink.close()
    _, heads = forward_kinematics(builtin_body.rig, poses)
    want = 100.0 * transform_points(t, heads)
    got = own_positions(camera_file, builtin_body.bone_names)
    np.testing.assert_allclose(got[1:], want, atol=1e-3)
    np.testing.assert_allclose(bvhio_positions(camera_file, builtin_body.bone_names, len(poses) + 1)[1:], want,
                               atol=1e-3)
    np.testing.assert_allclose(own_positions(world_file, builtin_body.bone_names), want, atol=1e-3)
    rest = got[0]
    assert rest[0] == pytest.approx([0.0, 100.0 * builtin_body.floor_offset, 0.0], abs=1e-3)  # pelvis over origin
    head = builtin_body.bone_names.index("head")
    assert rest[head, 1] > rest[0, 1] + 40  # upright
    rows = list(csv.DictReader((tmp_path / "poses.csv").open()))
    assert {r["coordinates"] for r in rows} == {"world"}
    first_root = [float(rows[0][name]) for name in ("tx", "ty", "tz")]
    assert first_root == pytest.approx(transform_points(t, poses[0, 0:3]), abs=1e-5)
