"""The protocol's JSON Schemas: valid schemas, messages the code builds pass them, broken ones fail
with the field named, and the committed examples stay valid."""

from __future__ import annotations

import copy
import json
import re
from dataclasses import replace

import jsonschema
import numpy as np
import pytest
from conftest import REPO
from scipy.spatial.transform import Rotation

from swarmpose.body.loader import load_body
from swarmpose.body.skeleton import EVAL_JOINTS, neutral_pose
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, ProtocolError
from swarmpose.core.world import WorldState
from swarmpose.messages import (
    POSE_NAMES,
    check_camera_id,
    decode,
    encode,
    frame_message,
    info_message,
    keys,
    schema,
    validate,
)
from swarmpose.tracking.result import BodyResult, posed_skeleton


def body_entry(result: BodyResult, body_id: int = 0) -> dict:
    """One body of a frame message, as the tracker writes it."""
    return replace(result, id=body_id).to_message()


def a_result(state: str = "tracking") -> BodyResult:
    body = load_body("builtin")
    h = neutral_pose()
    joints3d = body.posed_points(h[None], EVAL_JOINTS)[0]
    intr = Intrinsics.kinect_v1()
    joints2d = np.stack([intr.fx * joints3d[:, 0] / joints3d[:, 2] + intr.cx,
                         intr.fy * joints3d[:, 1] / joints3d[:, 2] + intr.cy], axis=1)
    joints3d[6] = np.nan   # an unknown joint
    return BodyResult(id=0, state=state, reason="", pose=h, joints3d=joints3d,
                       joints2d=joints2d, confidence=np.linspace(0, 1, len(EVAL_JOINTS)),
                       objective={"E": 12.5, "E_D": 3.0, "E_J": 3.5}, timings_ms={"pso": 410.0},
                       skeleton=posed_skeleton(body, h, intr))


def test_the_schemas_are_valid_draft_2020_12():
    for name in ("frame", "status", "info"):
        jsonschema.Draft202012Validator.check_schema(schema(name))
        assert schema(name)["properties"]["schema"]["const"] == f"swarmpose.{name}"


def test_a_frame_message_from_a_tracker_result_is_valid_and_round_trips():
    result = a_result()
    message = frame_message("cam0", 4, 133_333_333, 1_000, 251_000_000, [body_entry(result)],
                            timings_ms=result.timings_ms)
    validate(message)
    back = decode(encode(message))
    assert back == message and back["latency_ms"] == 250.999
    head = back["bodies"][0]["joints"]["head"]
    assert head["position_m"] == pytest.approx(result.joints3d[0], abs=1e-6)
    assert back["bodies"][0]["joints"]["left_wrist"]["position_m"] is None       # NaN -> null, never NaN
    assert len(back["bodies"][0]["pose"]) == len(POSE_NAMES) == 36


@pytest.mark.parametrize(("mutate", "where"), [
    (lambda m: m.pop("capture_ns"), "(top level)"),
    (lambda m: m["bodies"][0]["pose"].pop(), "bodies/0/pose"),
    (lambda m: m["bodies"][0]["joints"]["head"].update(confidence=1.5), "bodies/0/joints/head/confidence"),
    (lambda m: m["bodies"][0].update(state="dancing"), "bodies/0/state"),
    (lambda m: m.update(camera="a/b"), "camera"),
    (lambda m: m.update(version=1), "version"),
])
def test_broken_frame_messages_fail_naming_the_field(mutate, where):
    message = frame_message("cam0", 4, 0, 0, 0, [body_entry(a_result())])
    broken = copy.deepcopy(message)
    mutate(broken)
    with pytest.raises(ProtocolError, match=re.escape(f"invalid at {where}")):
        validate(broken)


def test_non_messages_are_rejected():
    with pytest.raises(ProtocolError, match="not JSON"):
        decode(b"\xff\xfe")
    with pytest.raises(ProtocolError, match="JSON list"):
        decode(b"[1, 2]")
    with pytest.raises(ProtocolError, match="not a swarmpose message"):
        validate({"schema": "other.thing"})
    with pytest.raises(ValueError):
        encode({"x": float("nan")})


def test_info_message_describes_skeleton_pose_and_camera():
    body = load_body("builtin")
    info = info_message("cam0", intrinsics=Intrinsics.kinect_v1(), body=body, body_spec="builtin",
                        source="folder:x", detector="simulated")
    validate(info)
    assert info["keys"] == keys("cam0") == {"frame": "swarmpose/cam0/frame", "status": "swarmpose/cam0/status",
                                            "alive": "swarmpose/cam0/alive", "info": "swarmpose/cam0/info"}
    skeleton = info["skeleton"]
    assert len(skeleton["joints"]) == 28 and skeleton["evaluation_joints"] == list(EVAL_JOINTS)
    assert set(EVAL_JOINTS) <= set(skeleton["joints"]) and skeleton["parents"][0] is None  # pelvis, the root
    parent = dict(zip(skeleton["joints"], skeleton["parents"]))
    assert [parent[j] for j in ("left_wrist", "left_elbow", "left_shoulder", "left_clavicle", "spine_chest",
                                "spine_navel")] == ["left_elbow", "left_shoulder", "left_clavicle", "spine_chest",
                                                    "spine_navel", "pelvis"]
    assert skeleton["links"] == [[p, c] for c, p in parent.items() if p is not None]
    assert info["pose_vector"]["names"][7] == "neck.roll" and len(info["pose_vector"]["limits_rad"]) == 29
    assert info["intrinsics"]["fx"] == 525.0 and info["body"]["bones"] == len(body.bone_names)
    validate(info_message("cam0"))          # before the first frame: no intrinsics, no body yet


def test_camera_ids_that_would_break_key_expressions_are_refused():
    for bad in ("", "a/b", "cam*", "a b", "x" * 65):
        with pytest.raises(ConfigError, match="camera id"):
            check_camera_id(bad)
    assert check_camera_id("kinect_0.left-1") == "kinect_0.left-1"


def test_the_committed_examples_are_valid():
    for name in ("frame", "status", "info"):
        example = json.loads((REPO / "protocol" / "examples" / f"{name}.json").read_text())
        validate(example)
        jsonschema.validate(example, json.loads((REPO / "protocol" / f"{name}.schema.json").read_text()))


def test_frame_messages_say_their_coordinates_and_carry_the_world_transform():
    from swarmpose.core.world import normal_of_angles, world_from_floor
    from swarmpose.tracking.result import FrameResult

    body = a_result()
    t = world_from_floor(normal_of_angles(10.0), 1.2, body.pose[0:3])
    state = WorldState(t[1, :3], float(t[1, 3]), "depth", 900, t)
    camera = validate(FrameResult(3, 0, (body,), world=state).to_message("cam0"))
    world = validate(FrameResult(3, 0, (body,), world=state, coordinates="world").to_message("cam0"))
    assert camera["coordinates"] == "camera" and world["coordinates"] == "world"
    assert camera["camera_to_world"] == world["camera_to_world"] == pytest.approx(t, abs=1e-6)
    head_cam, head_world = (m["bodies"][0]["joints"]["head"]["position_m"] for m in (camera, world))
    assert head_world == pytest.approx(t[:3, :3] @ np.asarray(head_cam) + t[:3, 3], abs=1e-5)  # by hand
    assert world["bodies"][0]["joints"]["left_wrist"]["position_m"] is None  # unknown stays null
    # world asked for but not known yet: camera coordinates, no transform
    early = validate(FrameResult(3, 0, (body,), coordinates="world").to_message("cam0"))
    assert early["coordinates"] == "camera" and early["camera_to_world"] is None
    for broken in ({**world, "coordinates": "floor"}, {**world, "camera_to_world": [[1, 0, 0, 0]] * 3}):
        with pytest.raises(ProtocolError, match="invalid at (coordinates|camera_to_world)"):
            validate(broken)
    info = validate(info_message("cam0", world={"coordinates": "world", **state.as_dict()}))
    assert info["world"]["floor"]["camera_height_m"] == pytest.approx(1.2)
    assert info["world"]["floor"]["pitch_deg"] == pytest.approx(10.0)
    assert info["skeleton"]["frame"].startswith("world")
    assert validate(info_message("cam0"))["world"] == {"coordinates": "camera", "floor": None, "camera_to_world": None}


def test_every_joint_of_the_full_set_has_a_unit_orientation_and_the_14_keep_their_values():
    result = a_result()
    message = validate(frame_message("cam0", 0, 0, 0, 0, [body_entry(result)]))
    joints = message["bodies"][0]["joints"]
    assert len(joints) == 28 and set(EVAL_JOINTS) <= set(joints)
    for e, name in enumerate(EVAL_JOINTS):  # positions, pixels and confidences as version 4 had them
        want = None if not np.all(np.isfinite(result.joints3d[e])) else pytest.approx(result.joints3d[e], abs=1e-6)
        assert joints[name]["position_m"] == want
        assert joints[name]["confidence"] == pytest.approx(result.confidence[e], abs=1e-3)
    for name, joint in joints.items():
        assert np.linalg.norm(joint["orientation_xyzw"]) == pytest.approx(1.0, abs=1e-5), name
        assert joint["orientation_xyzw"][3] >= 0
    # the neutral pose faces the camera: every frame is the root's, 180 degrees about x
    assert joints["left_elbow"]["orientation_xyzw"] == pytest.approx([1.0, 0.0, 0.0, 0.0], abs=1e-6)
    assert joints["pelvis"]["position_m"] == pytest.approx(result.pose[:3], abs=1e-6)
    api = result.joints
    assert list(api) == list(joints) and api["left_hand"].orientation_xyzw == pytest.approx([1.0, 0.0, 0.0, 0.0])
    assert api["left_wrist"].position_m is None and api["left_wrist"].orientation_xyzw is not None


def test_a_body_without_a_pose_has_null_orientations_and_no_extra_joints():
    result = replace(a_result(), pose=None, skeleton=None)
    joints = validate(frame_message("cam0", 0, 0, 0, 0, [body_entry(result)]))["bodies"][0]["joints"]
    assert all(j["orientation_xyzw"] is None for j in joints.values())
    assert joints["head"]["position_m"] is not None  # the 14 as given (a lifted body: positions, no pose)
    assert joints["pelvis"] == {"position_m": None, "orientation_xyzw": None, "pixel": None, "confidence": 0.0}


def test_world_coordinates_turn_the_orientations_by_the_camera_rotation():
    from swarmpose.core.world import normal_of_angles, world_from_floor
    from swarmpose.tracking.result import FrameResult

    body = replace(a_result(), pose=np.concatenate([[0.1, 0.2, 3.0], [0.9, 0.3, 0.2, 0.1], np.full(29, 0.1)]))
    body = replace(body, skeleton=posed_skeleton(load_body("builtin"), body.pose, Intrinsics.kinect_v1()))
    t = world_from_floor(normal_of_angles(10.0), 1.2, body.pose[0:3])
    state = WorldState(t[1, :3], float(t[1, 3]), "depth", 900, t)
    camera = FrameResult(3, 0, (body,), world=state).to_message("cam0")["bodies"][0]["joints"]
    world = validate(FrameResult(3, 0, (body,), world=state, coordinates="world").to_message("cam0"))
    world_joints = world["bodies"][0]["joints"]
    turn = Rotation.from_matrix(t[:3, :3])
    for name in ("pelvis", "left_elbow", "right_foot", "nose"):
        want = (turn * Rotation.from_quat(camera[name]["orientation_xyzw"])).as_matrix()
        got = Rotation.from_quat(world_joints[name]["orientation_xyzw"]).as_matrix()
        np.testing.assert_allclose(got, want, atol=1e-5, err_msg=name)
        assert world_joints[name]["position_m"] == pytest.approx(t[:3, :3] @ camera[name]["position_m"] + t[:3, 3],
                                                                 abs=1e-5)


def test_a_message_of_the_previous_version_is_refused_naming_the_version():
    old = json.loads((REPO / "protocol" / "examples" / "frame.json").read_text())
    old["version"] = 4
    for joint in old["bodies"][0]["joints"].values():
        joint.pop("orientation_xyzw")
    with pytest.raises(ProtocolError, match="invalid at version"):
        validate(old)


def test_json_rows_round_each_row_as_python_does_and_drop_rows_that_are_not_finite():
    """The message's vectorised rounding against Python's round() of each entry (json_vector)."""
    from swarmpose.messages.build import json_rows, json_vector

    rows = np.random.default_rng(3).normal(scale=5.0, size=(20000, 3))
    rows[7, 0], rows[11, 2], rows[12, 1] = np.nan, np.inf, -np.inf
    for digits in (2, 4, 6):
        got = json_rows(rows, digits)
        assert got == [json_vector(row, digits) for row in rows]
        assert got[7] is None and got[11] is None and got[12] is None and got[0] is not None
