"""glTF/GLB export and import of skinned bodies (swarmpose.body.gltf_write / gltf_read / gltf_rig).

The body under test is a small synthetic humanoid built here from tubes and a sphere,
so these tests do not depend on the MakeHuman or built-in body loaders.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest
import trimesh

from swarmpose.body.gltf_format import SYNTHETIC_ROOT
from swarmpose.body.gltf_read import load_glb
from swarmpose.body.gltf_rig import BONE_ROLES, canonical_bone_name
from swarmpose.body.gltf_write import save_glb
from swarmpose.body.kinematics import shortest_arc
from swarmpose.body.landmarks import face_landmarks, foot_landmarks
from swarmpose.body.skeleton import ANGLE_LIMITS, JOINT_INDEX, JOINT_NAMES, POINT_NAMES, POSE_DIM, TRACKING_JOINTS
from swarmpose.body.skinned import SkinnedBody, sparse_skin
from swarmpose.core.errors import AssetError

# name, parent, head, tail, tube radius, tracking joint (None = rigid), fraction
_CENTRE = [
    ("pelvis", None, (0, 0, 0), (0, 0.10, 0), 0.0, None, 1.0),
    ("spine_lower", "pelvis", (0, 0.10, 0), (0, 0.30, 0), 0.0, "spine", 0.5),
    ("spine_upper", "spine_lower", (0, 0.30, 0), (0, 0.50, 0), 0.0, "spine", 0.5),
    ("neck", "spine_upper", (0, 0.50, 0), (0, 0.60, 0), 0.05, "neck", 1.0),
    ("head", "neck", (0, 0.60, 0), (0, 0.80, 0), 0.0, None, 1.0),
]
_SIDE = [  # left side; the right side mirrors x
    ("clavicle", "spine_upper", (0.02, 0.45, 0), (0.18, 0.45, 0), 0.04, "collar"),
    ("upper_arm", "clavicle", (0.18, 0.45, 0), (0.42, 0.31, 0), 0.045, "shoulder"),
    ("forearm", "upper_arm", (0.42, 0.31, 0), (0.64, 0.18, 0), 0.04, "elbow"),
    ("hand", "forearm", (0.64, 0.18, 0), (0.78, 0.10, 0), 0.03, None),
    ("thigh", "pelvis", (0.09, -0.05, 0), (0.10, -0.48, 0.01), 0.07, "hip"),
    ("shin", "thigh", (0.10, -0.48, 0.01), (0.10, -0.90, -0.01), 0.05, "knee"),
    ("foot", "shin", (0.10, -0.90, -0.01), (0.10, -0.96, 0.18), 0.0, "ankle"),
]
_POINT_BONE = {"clavicle": "clavicle", "shoulder": "upper_arm", "elbow": "forearm", "wrist": "hand",
               "hip": "thigh", "knee": "shin", "ankle": "foot"}

MIXAMO = {"pelvis": "Hips", "spine_lower": "Spine", "spine_upper": "Spine1", "neck": "Neck", "head": "Head",
          **{f"{s}_{k}": f"{s.title()}{v}" for s in ("left", "right") for k, v in (
              ("clavicle", "Shoulder"), ("upper_arm", "Arm"), ("forearm", "ForeArm"), ("hand", "Hand"),
              ("thigh", "UpLeg"), ("shin", "Leg"), ("foot", "Foot"))}}
CMU = {**MIXAMO, "spine_lower": "LowerBack", "spine_upper": "Spine"}
UNREAL = {"pelvis": "pelvis", "spine_lower": "spine_01", "spine_upper": "spine_02", "neck": "neck_01", "head": "head",
          **{f"{s}_{k}": f"{v}_{s[0]}" for s in ("left", "right") for k, v in (
              ("clavicle", "clavicle"), ("upper_arm", "upperarm"), ("forearm", "lowerarm"), ("hand", "hand"),
              ("thigh", "thigh"), ("shin", "calf"), ("foot", "foot"))}}


def _tube(a, b, radius: float, sides: int = 8, rings: int = 4, cap: float = 0.01):
    """A closed cylinder from a to b with cone caps protruding ``cap`` beyond each end."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = (b - a) / np.linalg.norm(b - a)
    u = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    ang = 2 * np.pi * np.arange(sides) / sides
    circle = radius * (np.cos(ang)[:, None] * u + np.sin(ang)[:, None] * w)
    verts = [a + t * (b - a) + circle for t in np.linspace(0, 1, rings)]
    verts = np.concatenate(verts + [[a - cap * axis], [b + cap * axis]])
    tris, bottom, top = [], len(verts) - 2, len(verts) - 1
    for r in range(rings - 1):
        for s in range(sides):
            i, j = r * sides + s, r * sides + (s + 1) % sides
            tris += [(i, j, j + sides), (i, j + sides, i + sides)]
    for s in range(sides):
        tris += [(bottom, (s + 1) % sides, s), (top, (rings - 1) * sides + s, (rings - 1) * sides + (s + 1) % sides)]
    return verts, np.array(tris)


def _sphere(centre, radius: float, lon: int = 16, lat: int = 16):
    """A UV sphere with a vertex straight ahead (+Z) on the equator and poles on Y."""
    theta = np.pi * np.arange(1, lat) / lat
    phi = 2 * np.pi * np.arange(lon) / lon
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.sin(p), np.cos(t), np.sin(t) * np.cos(p)], -1).reshape(-1, 3)
    verts = np.asarray(centre) + radius * np.concatenate([ring, [[0, 1, 0], [0, -1, 0]]])
    tris, north, south = [], len(verts) - 2, len(verts) - 1
    for r in range(lat - 2):
        for s in range(lon):
            i, j = r * lon + s, r * lon + (s + 1) % lon
            tris += [(i, j + lon, j), (i, i + lon, j + lon)]
    for s in range(lon):
        tris += [(north, s, (s + 1) % lon), (south, (lat - 2) * lon + (s + 1) % lon, (lat - 2) * lon + s)]
    return verts, np.array(tris)


def _segment_distance(p, a, b):
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def make_body(metadata: dict | None = None) -> SkinnedBody:
    """A ~1.8 m low-poly humanoid: 19 bones, every tracking joint and named point."""
    bones = list(_CENTRE)
    for side, sx in (("left", 1.0), ("right", -1.0)):
        for name, parent, head, tail, radius, joint in _SIDE:
            mirror = np.array([sx, 1.0, 1.0])
            par = parent if parent in ("spine_upper", "pelvis") else f"{side}_{parent}"
            bones.append((f"{side}_{name}", par, tuple(np.multiply(head, mirror)), tuple(np.multiply(tail, mirror)),
                          radius, None if joint is None else f"{side}_{joint}", 1.0))
    names = [b[0] for b in bones]
    heads = np.array([b[2] for b in bones], float)
    tails = np.array([b[3] for b in bones], float)
    parts = [_tube((0, -0.08, 0), (0, 0.5, 0), 0.14), _sphere((0, 0.7, 0), 0.1)]
    for _, _, head, tail, radius, _, _ in bones:
        if radius > 0:
            parts.append(_tube(head, tail, radius))
    for sx in (1.0, -1.0):
        parts.append(_tube((0.10 * sx, -0.96, -0.06), (0.10 * sx, -0.96, 0.18), 0.04))
    verts, tris, offset = [], [], 0
    for v, t in parts:
        verts.append(v)
        tris.append(t + offset)
        offset += len(v)
    verts, tris = np.concatenate(verts), np.concatenate(tris).astype(np.int32)
    dist = np.stack([_segment_distance(verts, heads[b], tails[b]) for b in range(len(bones))], 1)
    skin_indices, skin_weights = sparse_skin(np.exp(-(dist - dist.min(1, keepdims=True)) / 0.015), len(verts))

    binds = np.broadcast_to(np.eye(4), (len(bones), 4, 4)).copy()
    for b in range(len(bones)):
        binds[b, :3, :3] = shortest_arc((0, 1, 0), tails[b] - heads[b])
        binds[b, :3, 3] = heads[b]
    idx = {n: i for i, n in enumerate(names)}
    points = {"spine": (heads[idx["spine_lower"]], "spine_lower"), "neck": (heads[idx["neck"]], "neck"),
              "head": (0.5 * (heads[idx["head"]] + [0, verts[:, 1].max(), 0]), "head"),
              "mid_hip": (0.5 * (heads[idx["left_thigh"]] + heads[idx["right_thigh"]]), "pelvis")}
    for side in ("left", "right"):
        for point, bone in _POINT_BONE.items():
            points[f"{side}_{point}"] = (heads[idx[f"{side}_{bone}"]], f"{side}_{bone}")
    for p, pos in face_landmarks(verts, points["head"][0], points["neck"][0]).items():
        points[p] = (pos, "head")
    for p, pos in foot_landmarks(verts, points["left_ankle"][0], points["right_ankle"][0]).items():
        points[p] = (pos, f"{p.split('_')[0]}_foot")
    return SkinnedBody(
        name="synthetic", vertices=verts, triangles=tris, skin_indices=skin_indices, skin_weights=skin_weights,
        bone_names=tuple(names), bone_parents=np.array([-1 if b[1] is None else idx[b[1]] for b in bones]),
        bone_heads=heads, bind_matrices=binds,
        bone_joint=np.array([-1 if b[5] is None else JOINT_INDEX[b[5]] for b in bones]),
        bone_fraction=np.array([b[6] for b in bones]), point_names=POINT_NAMES,
        point_bones=np.array([idx[points[p][1]] for p in POINT_NAMES]),
        point_rest=np.array([points[p][0] for p in POINT_NAMES], float),
        metadata=metadata if metadata is not None else {"height": 1.8, "note": "", "tags": [],
                                                        "nested": {"a": None, "b": [1.5, "x"]}},
    )


@pytest.fixture(scope="module")
def body() -> SkinnedBody:
    return make_body()


@pytest.fixture
def glb(body, tmp_path) -> Path:
    return save_glb(body, tmp_path / "body.glb")


def random_poses(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h = np.zeros((n, POSE_DIM))
    h[:, :3] = [0.1, -0.2, 3.0] + rng.normal(0, 0.2, (n, 3))
    q = rng.normal(size=(n, 4))
    h[:, 3:7] = q / np.linalg.norm(q, axis=1, keepdims=True)
    h[:, 7:] = rng.uniform(ANGLE_LIMITS[:, 0], ANGLE_LIMITS[:, 1], (n, len(ANGLE_LIMITS)))
    return h


def dense(b: SkinnedBody) -> np.ndarray:
    out = np.zeros((len(b.vertices), len(b.bone_names)))
    np.add.at(out, (np.arange(len(b.vertices))[:, None].repeat(4, 1), b.skin_indices), b.skin_weights)
    return out


def assert_same_posing(a: SkinnedBody, b: SkinnedBody, tol: float = 1e-5) -> None:
    h = random_poses(6)
    for method in ("lbs", "dqs"):
        np.testing.assert_allclose(b.pose(h, method), a.pose(h, method), atol=tol, rtol=0)
    np.testing.assert_allclose(b.posed_points(h, a.point_names), a.posed_points(h), atol=tol, rtol=0)


def append_accessor(gltf: gl.GLTF2, array: np.ndarray, component: int, kind: str, normalized: bool = False) -> int:
    """Append ``array`` to the GLB's binary blob as a new buffer view + accessor."""
    dtype = {gl.UNSIGNED_BYTE: "<u1", gl.UNSIGNED_SHORT: "<u2", gl.FLOAT: "<f4"}[component]
    blob = bytearray(gltf.binary_blob())
    blob.extend(b"\0" * (-len(blob) % 4))
    data = np.ascontiguousarray(array, dtype=dtype).tobytes()
    gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
    blob.extend(data)
    blob.extend(b"\0" * (-len(blob) % 4))
    gltf.accessors.append(gl.Accessor(bufferView=len(gltf.bufferViews) - 1, componentType=component,
                                      count=len(array), type=kind, normalized=normalized))
    gltf.buffers[0].byteLength = len(blob)
    gltf.set_binary_blob(bytes(blob))
    return len(gltf.accessors) - 1


def foreign(glb: Path, names: dict[str, str], prefix: str = "") -> gl.GLTF2:
    """The GLB with the swarmpose extras dropped and bones renamed (returned unsaved)."""
    gltf = gl.GLTF2.load(str(glb))
    for node in gltf.nodes:
        if node.name in names:
            node.name = prefix + names[node.name]
    for skin in gltf.skins:
        skin.extras = {}
    return gltf


def save(gltf: gl.GLTF2, path: Path) -> Path:
    gltf.save_binary(str(path))
    return path


# ---------------------------------------------------------------------------- round trip
def test_round_trip_keeps_everything(body, glb):
    back = load_glb(glb)
    assert back.name == body.name
    assert np.abs(body.vertices.astype(np.float32) - body.vertices).max() > 0  # POSITION alone would round
    # bit for bit: the exact positions, bind matrices and weights travel beside the float32 accessors
    np.testing.assert_array_equal(back.vertices, body.vertices)
    np.testing.assert_array_equal(back.triangles, body.triangles)
    np.testing.assert_array_equal(back.skin_indices, body.skin_indices)
    np.testing.assert_array_equal(back.skin_weights, body.skin_weights)
    assert back.bone_names == body.bone_names
    np.testing.assert_array_equal(back.bone_parents, body.bone_parents)
    np.testing.assert_array_equal(back.bone_heads, body.bone_heads)
    np.testing.assert_array_equal(back.bind_matrices, body.bind_matrices)
    np.testing.assert_array_equal(back.bone_joint, body.bone_joint)
    np.testing.assert_array_equal(back.bone_fraction, body.bone_fraction)
    assert back.point_names == body.point_names
    np.testing.assert_array_equal(back.point_bones, body.point_bones)
    np.testing.assert_array_equal(back.point_rest, body.point_rest)
    assert back.metadata == body.metadata


def test_round_trip_poses_identically(body, glb):
    assert_same_posing(body, load_glb(glb))


def test_positions_edited_by_another_tool_win_over_the_exact_ones(body, glb, tmp_path):
    """A tool that moves POSITION but keeps the swarmpose extras leaves stale exact positions: the
    edit must win (the exact copy is used only when all of it lies within 1e-6 of POSITION)."""
    gltf = gl.GLTF2.load(str(glb))
    acc = gltf.accessors[gltf.meshes[0].primitives[0].attributes.POSITION]
    view = gltf.bufferViews[acc.bufferView]
    blob = bytearray(gltf.binary_blob())
    start = view.byteOffset or 0
    xyz = np.frombuffer(bytes(blob[start:start + view.byteLength]), "<f4").reshape(-1, 3).copy()
    xyz[:, 1] += 0.01
    blob[start:start + view.byteLength] = xyz.tobytes()
    gltf.set_binary_blob(bytes(blob))
    back = load_glb(save(gltf, tmp_path / "edited.glb"))
    np.testing.assert_allclose(back.vertices - body.vertices, np.tile([0, 0.01, 0], (len(body.vertices), 1)),
                               atol=1e-6, rtol=0)


def test_a_file_written_before_the_exact_copies_reads_its_float32_accessors(body, glb, tmp_path):
    """Files of earlier versions have no ``exact`` extras: the body comes from the accessors, within
    float32 precision of the original."""
    gltf = gl.GLTF2.load(str(glb))
    del gltf.skins[0].extras["swarmpose"]["exact"]
    back = load_glb(save(gltf, tmp_path / "older.glb"))
    np.testing.assert_array_equal(back.vertices, body.vertices.astype(np.float32).astype(np.float64))
    assert 0 < np.abs(back.bind_matrices - body.bind_matrices).max() < 1e-6


def test_gltf_with_embedded_buffer_round_trips(body, tmp_path):
    path = save_glb(body, tmp_path / "body.gltf")
    assert json.loads(path.read_text())["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")
    back = load_glb(path)
    np.testing.assert_array_equal(back.vertices, body.vertices)
    np.testing.assert_array_equal(back.bind_matrices, body.bind_matrices)
    assert back.metadata == body.metadata
    assert_same_posing(body, back)


def test_gltf_with_adjacent_bin_loads(body, glb, tmp_path):
    gl.GLTF2.load(str(glb)).save_json(str(tmp_path / "split.gltf"))
    assert (tmp_path / "split.bin").is_file()
    back = load_glb(tmp_path / "split.gltf")
    np.testing.assert_allclose(back.vertices, body.vertices, atol=1e-6, rtol=0)
    (tmp_path / "split.bin").unlink()
    with pytest.raises(AssetError, match="split.gltf.*buffer 0"):
        load_glb(tmp_path / "split.gltf")


def test_glb_is_structurally_valid(body, glb):
    data = glb.read_bytes()
    magic, version, length = struct.unpack("<4sII", data[:12])
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack("<I4s", data[12:20])
    assert json_type == b"JSON" and json_len % 4 == 0
    doc = json.loads(data[20:20 + json_len])
    bin_len, bin_type = struct.unpack("<I4s", data[20 + json_len:28 + json_len])
    assert bin_type == b"BIN\0" and bin_len % 4 == 0 and 28 + json_len + bin_len == len(data)
    binary = data[28 + json_len:]
    assert doc["asset"]["version"] == "2.0" and doc["buffers"] == [{"byteLength": bin_len}]
    for view in doc["bufferViews"]:
        assert view.get("byteOffset", 0) % 4 == 0 and view.get("byteOffset", 0) + view["byteLength"] <= bin_len
    sizes = {5121: 1, 5123: 2, 5125: 4, 5126: 4}
    widths = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
    for acc in doc["accessors"]:
        view = doc["bufferViews"][acc["bufferView"]]
        assert acc["count"] * sizes[acc["componentType"]] * widths[acc["type"]] <= view["byteLength"]
    prim = doc["meshes"][0]["primitives"][0]
    assert prim.get("mode", 4) == 4
    pos = doc["accessors"][prim["attributes"]["POSITION"]]
    view = doc["bufferViews"][pos["bufferView"]]
    xyz = np.frombuffer(binary, "<f4", pos["count"] * 3, view.get("byteOffset", 0)).reshape(-1, 3)
    np.testing.assert_array_equal(xyz, body.vertices.astype(np.float32))
    assert pos["min"] == xyz.min(0).tolist() and pos["max"] == xyz.max(0).tolist()
    types = {k: (doc["accessors"][v]["componentType"], doc["accessors"][v]["type"])
             for k, v in prim["attributes"].items()}
    assert types["JOINTS_0"] == (5123, "VEC4") and types["WEIGHTS_0"] == (5126, "VEC4")
    assert doc["accessors"][prim["indices"]]["componentType"] == 5125
    skin = doc["skins"][0]
    assert len(skin["joints"]) == len(body.bone_names)
    assert doc["accessors"][skin["inverseBindMatrices"]]["type"] == "MAT4"
    scene_nodes = doc["scenes"][doc["scene"]]["nodes"]
    assert skin["skeleton"] in scene_nodes and any("mesh" in doc["nodes"][n] for n in scene_nodes)
    assert skin["extras"]["swarmpose"]["version"] >= 1
    # node TRS chained from the root gives each bone's bind matrix (independent of load_glb)
    parent = {c: i for i, n in enumerate(doc["nodes"]) for c in n.get("children", [])}
    for b, node_index in enumerate(skin["joints"]):
        m, n = np.eye(4), node_index
        while n is not None:
            node = doc["nodes"][n]
            x, y, z, w = node.get("rotation", [0, 0, 0, 1])
            local = np.eye(4)
            local[:3, :3] = trimesh.transformations.quaternion_matrix([w, x, y, z])[:3, :3]
            local[:3, 3] = node.get("translation", [0, 0, 0])
            m, n = local @ m, parent.get(n)
        np.testing.assert_allclose(m, body.bind_matrices[b], atol=1e-9)


def test_trimesh_reads_same_mesh(body, glb):
    mesh = trimesh.load(str(glb), force="mesh", process=False)
    assert len(mesh.vertices) == len(body.vertices)
    assert len(mesh.faces) == len(body.triangles)
    np.testing.assert_allclose(mesh.bounds, [body.vertices.min(0), body.vertices.max(0)], atol=1e-6)


# ---------------------------------------------------------------------------- foreign rigs
@pytest.mark.parametrize("names, prefix", [(MIXAMO, "mixamorig:"), (MIXAMO, ""), (CMU, ""), (UNREAL, ""),
                                           ({}, "")], ids=["mixamorig", "mixamo", "cmu", "unreal", "swarmpose"])
def test_foreign_rig_maps_by_bone_name(body, glb, tmp_path, names, prefix):
    back = load_glb(save(foreign(glb, names, prefix), tmp_path / "foreign.glb"))
    assert back.metadata.get("rig") == "mapped by bone names"
    assert back.bone_names == tuple(prefix + names[n] if n in names else n for n in body.bone_names)
    assert {int(j) for j in back.bone_joint if j >= 0} == set(range(len(TRACKING_JOINTS)))
    spine = back.bones_of_joint("spine")
    assert len(spine) == 2 and back.bone_fraction[spine].sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(back.bone_joint, body.bone_joint)
    np.testing.assert_allclose(back.bone_fraction, body.bone_fraction)
    for side in ("left", "right"):
        for point, bone in _POINT_BONE.items():
            expected = body.bone_heads[body.bone_names.index(f"{side}_{bone}")]
            np.testing.assert_allclose(back.point(f"{side}_{point}"), expected, atol=1e-6)
    np.testing.assert_allclose(back.point("spine"), body.bone_heads[body.bone_names.index("spine_lower")], atol=1e-6)
    np.testing.assert_allclose(back.point("neck"), body.bone_heads[body.bone_names.index("neck")], atol=1e-6)
    np.testing.assert_allclose(back.point("head"), [0, 0.7, 0], atol=1e-6)  # between head bone and crown
    assert back.point_names == body.point_names
    np.testing.assert_allclose(back.point_rest, body.point_rest, atol=1e-6)
    np.testing.assert_array_equal(back.point_bones, body.point_bones)
    assert_same_posing(body, back)


@pytest.mark.parametrize("name, role", [
    ("mixamorig:LeftUpLeg", "left_thigh"), ("mixamorig_LeftUpLeg", "left_thigh"), ("mixamorig1:RightArm",
    "right_upper_arm"), ("Armature|Hips", "pelvis"), ("LHipJoint", "left_hip_joint"), ("LowerBack", "spine"),
    ("Neck1", "neck"), ("RightToeBase", "right_toe"), ("left_clavicle", "left_clavicle"), ("left_shin", "left_shin"),
    ("calf_r", "right_shin"), ("Bip01 L Thigh", "left_thigh"), ("LeftForeArm", "left_forearm"),
])
def test_name_table(name, role):
    assert BONE_ROLES[canonical_bone_name(name)] == role


def test_foreign_rig_missing_bone_is_named(glb, tmp_path):
    gltf = foreign(glb, {**MIXAMO, "left_forearm": "Elbowish"})
    with pytest.raises(AssetError, match=r"left_forearm.*Elbowish"):
        load_glb(save(gltf, tmp_path / "missing.glb"))


def test_foreign_rig_facing_backwards_is_refused(glb, tmp_path):
    swapped = {k: v.replace("Left", "Tmp").replace("Right", "Left").replace("Tmp", "Right") for k, v in MIXAMO.items()}
    with pytest.raises(AssetError, match=r"does not face \+Z"):
        load_glb(save(foreign(glb, swapped), tmp_path / "backwards.glb"))


def test_centimetre_armature_is_scaled_by_node_transforms(body, glb, tmp_path):
    """Vertices and IBMs in cm with the mesh under a 0.01-scaled node load in metres."""
    gltf = foreign(glb, MIXAMO)
    prim = gltf.meshes[0].primitives[0]
    prim.attributes.POSITION = append_accessor(gltf, body.vertices * 100, gl.FLOAT, gl.VEC3)
    prim.attributes.NORMAL = None
    ibm = np.linalg.inv(body.bind_matrices) @ np.diag([0.01, 0.01, 0.01, 1.0])
    gltf.skins[0].inverseBindMatrices = append_accessor(gltf, ibm.transpose(0, 2, 1).reshape(-1, 16),
                                                        gl.FLOAT, gl.MAT4)
    gltf.nodes.append(gl.Node(name="Armature", scale=[0.01, 0.01, 0.01], children=[0]))
    gltf.scenes[0].nodes = [len(gltf.nodes) - 1] + gltf.scenes[0].nodes[1:]
    back = load_glb(save(gltf, tmp_path / "cm.glb"))
    np.testing.assert_allclose(back.vertices, body.vertices, atol=1e-6)
    np.testing.assert_allclose(back.bind_matrices, body.bind_matrices, atol=1e-6)
    assert_same_posing(body, back)


def test_shuffled_skin_joints_are_reordered_parents_first(body, glb, tmp_path):
    gltf = gl.GLTF2.load(str(glb))
    skin = gltf.skins[0]
    perm = np.random.default_rng(3).permutation(len(body.bone_names))  # new slot k holds old bone perm[k]
    new_slot = np.argsort(perm)
    skin.joints = [skin.joints[p] for p in perm]
    ibm = np.linalg.inv(body.bind_matrices)[perm]
    skin.inverseBindMatrices = append_accessor(gltf, ibm.transpose(0, 2, 1).reshape(-1, 16), gl.FLOAT, gl.MAT4)
    gltf.meshes[0].primitives[0].attributes.JOINTS_0 = append_accessor(
        gltf, new_slot[body.skin_indices], gl.UNSIGNED_SHORT, gl.VEC4)
    ext = skin.extras["swarmpose"]
    ext["bone_joint"] = [ext["bone_joint"][p] for p in perm]
    ext["bone_fraction"] = [ext["bone_fraction"][p] for p in perm]
    for point in ext["points"]:
        point["bone"] = int(new_slot[point["bone"]])
    back = load_glb(save(gltf, tmp_path / "shuffled.glb"))
    assert back.bone_names[0] == "pelvis" and sorted(back.bone_names) == sorted(body.bone_names)
    assert all(back.bone_parents[b] < b for b in range(1, len(back.bone_names)))
    for b, name in enumerate(back.bone_names):
        old = body.bone_names.index(name)
        parent = back.bone_parents[b]
        assert (body.bone_parents[old] < 0 if parent < 0 else
                body.bone_names[body.bone_parents[old]] == back.bone_names[parent])
        assert back.bone_joint[b] == body.bone_joint[old]
        assert [back.bone_names[p] for p in back.point_bones] == [body.bone_names[p] for p in body.point_bones]
    assert_same_posing(body, back)


def test_several_root_joints_get_a_synthetic_root(body, glb, tmp_path):
    gltf = foreign(glb, {})
    gltf.nodes.append(gl.Node(name="prop", translation=[0.3, 0.2, 0.1]))
    gltf.scenes[0].nodes.append(len(gltf.nodes) - 1)
    gltf.skins[0].joints.append(len(gltf.nodes) - 1)
    prop_bind = np.eye(4)
    prop_bind[:3, 3] = [0.3, 0.2, 0.1]
    ibm = np.linalg.inv(np.concatenate([body.bind_matrices, prop_bind[None]]))
    gltf.skins[0].inverseBindMatrices = append_accessor(gltf, ibm.transpose(0, 2, 1).reshape(-1, 16),
                                                        gl.FLOAT, gl.MAT4)
    back = load_glb(save(gltf, tmp_path / "roots.glb"))
    assert back.bone_names[0] == SYNTHETIC_ROOT and back.bone_names[1] == "pelvis"
    assert list(back.bone_parents[:2]) == [-1, 0] and back.bone_parents[back.bone_names.index("prop")] == 0
    np.testing.assert_allclose(back.bone_heads[0], 0, atol=1e-7)
    assert_same_posing(body, back)


# ---------------------------------------------------------------------------- influences
def test_eight_influences_keep_the_four_largest(body, glb, tmp_path):
    rng = np.random.default_rng(7)
    v, b = len(body.vertices), len(body.bone_names)
    idx = np.stack([rng.choice(b, 8, replace=False) for _ in range(v)])
    w = rng.uniform(0.05, 1.0, (v, 8))
    gltf = gl.GLTF2.load(str(glb))
    attrs = gltf.meshes[0].primitives[0].attributes
    attrs.JOINTS_0 = append_accessor(gltf, idx[:, :4], gl.UNSIGNED_SHORT, gl.VEC4)
    attrs.WEIGHTS_0 = append_accessor(gltf, w[:, :4], gl.FLOAT, gl.VEC4)
    attrs.JOINTS_1 = append_accessor(gltf, idx[:, 4:], gl.UNSIGNED_BYTE, gl.VEC4)
    w1 = np.round(w[:, 4:] * 65535)  # the second set as normalised unsigned shorts
    attrs.WEIGHTS_1 = append_accessor(gltf, w1, gl.UNSIGNED_SHORT, gl.VEC4, normalized=True)
    back = load_glb(save(gltf, tmp_path / "eight.glb"))
    w32 = np.concatenate([w[:, :4].astype(np.float32).astype(np.float64), w1 / 65535], axis=1)
    top = np.argsort(-w32, axis=1)[:, :4]
    expected = np.zeros((v, b))
    rows = np.arange(v)[:, None]
    expected[rows, idx[rows, top]] = w32[rows, top] / w32[rows, top].sum(1, keepdims=True)
    np.testing.assert_allclose(dense(back), expected, atol=1e-6)
    assert np.all(np.count_nonzero(dense(back), axis=1) == 4)


def test_normalised_byte_weights(body, glb, tmp_path):
    gltf = gl.GLTF2.load(str(glb))
    attrs = gltf.meshes[0].primitives[0].attributes
    q = np.round(body.skin_weights * 255)
    q[np.arange(len(q)), np.argmax(q, 1)] += 255 - q.sum(1)  # quantised weights summing to 255
    attrs.JOINTS_0 = append_accessor(gltf, body.skin_indices, gl.UNSIGNED_BYTE, gl.VEC4)
    attrs.WEIGHTS_0 = append_accessor(gltf, q, gl.UNSIGNED_BYTE, gl.VEC4, normalized=True)
    back = load_glb(save(gltf, tmp_path / "bytes.glb"))
    expected = np.zeros_like(dense(back))
    np.add.at(expected, (np.arange(len(q))[:, None].repeat(4, 1), body.skin_indices), q / 255)
    np.testing.assert_allclose(dense(back), expected, atol=1e-6)


# ---------------------------------------------------------------------------- errors
def test_missing_file(tmp_path):
    with pytest.raises(AssetError, match="nope.glb.*no such file"):
        load_glb(tmp_path / "nope.glb")


def test_text_file_is_not_gltf(tmp_path):
    path = tmp_path / "notes.glb"
    path.write_text("these are not the triangles you are looking for\n")
    with pytest.raises(AssetError, match="notes.glb.*not a glTF"):
        load_glb(path)


def test_glb_without_skin(glb, tmp_path):
    gltf = gl.GLTF2.load(str(glb))
    gltf.skins = []
    gltf.nodes[0].skin = None
    attrs = gltf.meshes[0].primitives[0].attributes
    attrs.JOINTS_0 = attrs.WEIGHTS_0 = None
    with pytest.raises(AssetError, match="unskinned.glb.*no skinned mesh"):
        load_glb(save(gltf, tmp_path / "unskinned.glb"))


def test_glb_without_mesh(glb, tmp_path):
    gltf = gl.GLTF2.load(str(glb))
    gltf.meshes = []
    gltf.nodes[0].mesh = None
    with pytest.raises(AssetError, match="empty.glb.*no mesh"):
        load_glb(save(gltf, tmp_path / "empty.glb"))


def test_non_triangle_primitive(glb, tmp_path):
    gltf = gl.GLTF2.load(str(glb))
    gltf.meshes[0].primitives[0].mode = gl.LINES
    with pytest.raises(AssetError, match="lines.glb.*triangulate"):
        load_glb(save(gltf, tmp_path / "lines.glb"))


def test_every_tracking_joint_round_trips_by_name(glb):
    ext = gl.GLTF2.load(str(glb)).skins[0].extras["swarmpose"]
    assert {j for j in ext["bone_joint"] if j is not None} == set(JOINT_NAMES)
