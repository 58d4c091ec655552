"""The ROS 2 bag of ``--out`` (``poses_ros2/``): read back with readers other than the writer.

Oracles: ``rosbags``' ``AnyReader`` (its rosbag2 reader, which reads ``metadata.yaml`` and
decodes the CDR with the bag's own message definitions) and the ``mcap`` package's reader of the
raw MCAP file (channels, schemas, log times); the transforms are composed along their parent frame
ids with scipy's ``Rotation`` and compared with ``poses.jsonl``; the parents expected are
docs/conventions.md's table, written out here.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarmpose.cli.main import main
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import OutputError
from swarmpose.publish.files import open_recording
from swarmpose.publish.ros_bag import RosBagSink
from swarmpose.sources.base import Frame

FAST = ["--particles", "4", "--generations", "2", "--no-overlay", "-q"]
EXAMPLE = Path(__file__).resolve().parents[2] / "protocol" / "examples" / "frame.json"
PARENTS = {  # docs/conventions.md, "The full joint set": a joint -> its parent joint
    "spine_navel": "pelvis", "spine_chest": "spine_navel", "neck": "spine_chest", "head": "neck", "nose": "head",
    "left_eye": "head", "right_ear": "head", "left_clavicle": "spine_chest", "right_shoulder": "right_clavicle",
    "left_elbow": "left_shoulder", "left_wrist": "left_elbow", "right_hand": "right_wrist", "left_hip": "pelvis",
    "right_knee": "right_hip", "left_ankle": "left_knee", "right_foot": "right_ankle",
}


@pytest.fixture(scope="module")
def builtin_body():
    from swarmpose.body.loader import load_body

    return load_body("builtin")


def read_bag(folder: Path) -> list[tuple[str, int, object]]:
    """Every message of the bag as (topic, log time ns, decoded message), by rosbags' reader."""
    from rosbags.highlevel import AnyReader

    with AnyReader([folder]) as reader:
        return [(c.topic, t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()]


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def compose(transforms) -> dict[str, tuple[str, np.ndarray, Rotation]]:
    """Each child frame's root frame, position and rotation in it, composed along the parents."""
    edges = {t.child_frame_id: t for t in transforms}
    out: dict[str, tuple[str, np.ndarray, Rotation]] = {}

    def place(frame: str):
        if frame not in edges:
            return frame, np.zeros(3), Rotation.identity()
        if frame not in out:
            t = edges[frame]
            root, x, r = place(t.header.frame_id)
            tr, q = t.transform.translation, t.transform.rotation
            out[frame] = (root, x + r.apply([tr.x, tr.y, tr.z]), r * Rotation.from_quat([q.x, q.y, q.z, q.w]))
        return out[frame]

    for child in edges:
        place(child)
    return out


def check_tf_against_poses(messages: list[dict], bag: list, root: str) -> None:
    """Every frame's TF tree composes to poses.jsonl's joints, one tree per person, under ``root``."""
    tf = [(t, m) for topic, t, m in bag if topic == "/tf"]
    assert [t for t, _ in tf] == [m["capture_ns"] for m in messages]
    for message, (log_time, tf_message) in zip(messages, tf):
        joint_tf = [t for t in tf_message.transforms if t.child_frame_id.startswith("swarmpose/")]
        assert all(stamp_ns(t.header) == log_time for t in tf_message.transforms)
        placed = compose(tf_message.transforms)
        ids = {b["id"] for b in message["bodies"] if b["joints"]["pelvis"]["position_m"] is not None}
        assert len(joint_tf) == 28 * len(ids) and ids
        for body in message["bodies"]:
            prefix = f"swarmpose/id{body['id']}/"
            parent_of = {t.child_frame_id: t.header.frame_id for t in joint_tf}
            assert parent_of[prefix + "pelvis"] == root
            for child, parent in PARENTS.items():
                assert parent_of[prefix + child] == prefix + parent
            for name, joint in body["joints"].items():
                frame_root, x, r = placed[prefix + name]
                assert frame_root == root
                np.testing.assert_allclose(x, joint["position_m"], atol=1e-4)
                q = r.as_quat()
                q = q if np.dot(q, joint["orientation_xyzw"]) >= 0 else -q
                np.testing.assert_allclose(q, joint["orientation_xyzw"], atol=1e-4)
        for t in joint_tf:
            q = t.transform.rotation
            assert abs(np.linalg.norm([q.x, q.y, q.z, q.w]) - 1.0) < 1e-9


def test_track_writes_a_bag_whose_tf_tree_composes_to_the_poses(wave_sequence, tmp_path):
    out = tmp_path / "out"
    assert main(["track", str(wave_sequence), "--out", str(out), "--frames", "3", *FAST]) == 0
    messages = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
    bag_dir = out / "poses_ros2"
    assert sorted(p.name for p in bag_dir.iterdir()) == ["metadata.yaml", "poses_ros2.mcap"]
    bag = read_bag(bag_dir)
    check_tf_against_poses(messages, bag, "camera0")
    markers = [(t, m) for topic, t, m in bag if topic == "/swarmpose/markers"]
    assert [t for t, _ in markers] == [m["capture_ns"] for m in messages]
    for message, (_, array) in zip(messages, markers):
        joints = message["bodies"][0]["joints"]
        lines, spheres = array.markers
        assert (lines.ns, lines.id, lines.type, spheres.ns, spheres.id, spheres.type) == ("id0", 0, 5, "id0", 1, 7)
        assert lines.header.frame_id == spheres.header.frame_id == "camera0"
        points = np.array([[p.x, p.y, p.z] for p in spheres.points])
        np.testing.assert_allclose(points, [j["position_m"] for j in joints.values()], atol=1e-9)
        ends = np.array([[p.x, p.y, p.z] for p in lines.points]).reshape(-1, 2, 3)
        wrist = [pair for pair in ends if np.allclose(pair[1], joints["left_wrist"]["position_m"])]
        np.testing.assert_allclose(wrist[0][0], joints["left_elbow"]["position_m"])  # the forearm's line
        assert len(ends) == 27  # a tree of 28 joints
    # the raw MCAP file, by the mcap package: topics, schemas, encodings and log times
    from mcap.reader import make_reader

    with (bag_dir / "poses_ros2.mcap").open("rb") as f:
        raw = [(channel.topic, schema.name, channel.message_encoding, msg.log_time)
               for schema, channel, msg in make_reader(f).iter_messages()]
    assert sorted({r[:3] for r in raw}) == [("/swarmpose/markers", "visualization_msgs/msg/MarkerArray", "cdr"),
                                            ("/tf", "tf2_msgs/msg/TFMessage", "cdr")]
    assert sorted(r[3] for r in raw if r[0] == "/tf") == [m["capture_ns"] for m in messages]


def test_world_coordinates_hang_the_people_under_world(wave_sequence, tmp_path):
    out = tmp_path / "world"
    assert main(["track", str(wave_sequence), "--out", str(out), "--frames", "2", "--coordinates", "world",
                 *FAST]) == 0
    messages = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
    assert all(m["coordinates"] == "world" and m["camera_to_world"] for m in messages)
    bag = read_bag(out / "poses_ros2")
    check_tf_against_poses(messages, bag, "world")
    for message, (_, _, tf_message) in zip(messages, [b for b in bag if b[0] == "/tf"]):
        camera = [t for t in tf_message.transforms if t.child_frame_id == "camera0"]
        assert len(camera) == 1 and camera[0].header.frame_id == "world"
        tr, q = camera[0].transform.translation, camera[0].transform.rotation
        matrix = np.asarray(message["camera_to_world"])
        np.testing.assert_allclose([tr.x, tr.y, tr.z], matrix[:3, 3], atol=1e-9)
        np.testing.assert_allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), matrix[:3, :3], atol=1e-6)


def test_no_ros_bag_leaves_it_out(wave_sequence, tmp_path):
    assert main(["track", str(wave_sequence), "--out", str(tmp_path), "--frames", "1", "--no-ros-bag", *FAST]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poses.bvh", "poses.csv", "poses.jsonl", "run.json"]


def example_message(capture_ns: int, body_ids: tuple[int, ...]) -> dict:
    """protocol/examples/frame.json at ``capture_ns`` with its body as each of ``body_ids``,
    without its camera transform."""
    message = json.loads(EXAMPLE.read_text())
    body = message["bodies"][0]
    message.update(capture_ns=capture_ns, camera_to_world=None, bodies=[{**body, "id": i} for i in body_ids])
    return message


def test_markers_keep_each_person_in_its_namespace_and_delete_who_leaves(tmp_path):
    sink = RosBagSink(tmp_path / "bag")
    for k, ids in enumerate([(0, 3), (0, 3), (3,), ()]):
        sink.frame(example_message(1_000 + k, ids))
    sink.close()
    bag = read_bag(tmp_path / "bag")
    arrays = [m for topic, _, m in bag if topic == "/swarmpose/markers"]
    seen = [sorted((m.ns, m.id, m.action) for m in a.markers) for a in arrays]
    both = [("id0", 0, 0), ("id0", 1, 0), ("id3", 0, 0), ("id3", 1, 0)]
    assert seen == [both, both, [("id0", 0, 2), ("id0", 1, 2), ("id3", 0, 0), ("id3", 1, 0)],
                    [("id3", 0, 2), ("id3", 1, 2)]]
    assert [t for topic, t, _ in bag if topic == "/tf"] == [1_000, 1_001, 1_002]  # the empty frame has none
    colours = {(m.ns, (m.color.r, m.color.g, m.color.b)) for a in arrays[:2] for m in a.markers}
    assert len(colours) == 2  # one colour per person, the same on every frame


def test_the_depth_goes_in_as_an_image_in_metres_with_its_camera(tmp_path):
    depth = np.random.default_rng(0).uniform(0.5, 4.0, size=(6, 8)).astype(np.float32)
    depth[2, 3] = 0.0
    intrinsics = Intrinsics(8, 6, 5.0, 6.0, 3.5, 2.5)
    sink = RosBagSink(tmp_path / "bag", depth=True)
    sink.frame(example_message(7, (0,)), Frame(0, 7, depth, None, intrinsics))
    sink.frame(example_message(8, (0,)), None)  # a skipped frame: no depth
    sink.close()
    bag = read_bag(tmp_path / "bag")
    (_, t_image, image), = [b for b in bag if b[0] == "/swarmpose/depth/image"]
    (_, t_info, info), = [b for b in bag if b[0] == "/swarmpose/depth/camera_info"]
    assert t_image == t_info == 7 and image.header.frame_id == info.header.frame_id == "demo"
    assert (image.encoding, image.width, image.height, image.step) == ("32FC1", 8, 6, 32)
    np.testing.assert_array_equal(np.frombuffer(bytes(image.data), dtype="<f4").reshape(6, 8), depth)
    np.testing.assert_allclose(np.reshape(info.k, (3, 3)), [[5.0, 0, 3.5], [0, 6.0, 2.5], [0, 0, 1]])


def test_a_reused_output_folder_gets_this_runs_bag(tmp_path, builtin_body):
    for capture_ns in (111, 222):  # the second run replaces the first's bag
        sinks = open_recording(tmp_path, builtin_body, overlay=False)
        for sink in sinks:
            sink.frame(example_message(capture_ns, (0,)), None)
            sink.close()
    assert [t for topic, t, _ in read_bag(tmp_path / "poses_ros2") if topic == "/tf"] == [222]
    for sink in open_recording(tmp_path, builtin_body, overlay=False, ros_bag=False):  # --no-ros-bag
        sink.close()
    assert not (tmp_path / "poses_ros2").exists()  # an earlier run's bag is not left beside other poses


def test_something_else_in_the_bags_place_is_refused_and_kept(tmp_path, builtin_body):
    (tmp_path / "a" / "poses_ros2").mkdir(parents=True)
    (tmp_path / "a" / "poses_ros2" / "notes.txt").write_text("the user's own")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "poses_ros2").write_text("a file")
    for folder in ("a", "b"):
        with pytest.raises(OutputError, match=r"poses_ros2 is in the way of the ROS 2 bag.*--no-ros-bag"):
            open_recording(tmp_path / folder, builtin_body, overlay=False)
        for sink in open_recording(tmp_path / folder, builtin_body, overlay=False, ros_bag=False):
            sink.close()
    assert (tmp_path / "a" / "poses_ros2" / "notes.txt").read_text() == "the user's own"
    assert (tmp_path / "b" / "poses_ros2").read_text() == "a file"


def test_without_rosbags_the_other_files_are_written_and_the_fix_is_named(tmp_path, builtin_body, monkeypatch,
                                                                          caplog):
    for name in [m for m in sys.modules if m == "rosbags" or m.startswith("rosbags.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "rosbags", None)  # as where it is not installed: import fails
    with caplog.at_level("WARNING"):
        sinks = open_recording(tmp_path, builtin_body, overlay=False)
    for sink in sinks:
        sink.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poses.bvh", "poses.csv", "poses.jsonl"]
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and "pip install rosbags" in warnings[0] and "--no-ros-bag" in warnings[0]
