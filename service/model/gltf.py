"""glTF 2.0 / GLB import and export of :class:`SkinnedBody` (through pygltflib).

The body frame (X = the subject's left, Y up, Z forward, metres) *is* glTF's frame for
a character facing +Z, so no axis conversion happens either way.

Export (:func:`save_glb`) writes one mesh (POSITION, NORMAL, JOINTS_0 uint16, WEIGHTS_0
float32, uint32 indices), one skin whose joints are one node per bone (local TRS =
``inv(parent bind) @ bind``, inverse bind matrices = ``inv(bind)``), and keeps what glTF
has no place for (tracking-joint mapping, named points, metadata) in ``skin.extras``
under ``"swarmpose"``. Import (:func:`load_glb`) restores those extras exactly, or maps
a foreign rig (CMU/MotionBuilder, Mixamo, Unreal, Unity-humanoid or swarmpose bone
names) onto the tracking skeleton by bone name.
"""

from __future__ import annotations

import base64
import heapq
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pygltflib as gl

from ..errors import AssetError, OutputError, ShapeError
from ..kinematics import matrix_to_quaternion, quaternion_to_matrix
from .body import MAX_INFLUENCES, SkinnedBody, sparse_skin
from .landmarks import face_landmarks, foot_landmarks
from .skeleton import JOINT_INDEX, JOINT_NAMES, POINT_NAMES

EXTRAS_KEY = "swarmpose"
FORMAT_NAME = "swarmpose.skinned-body"
FORMAT_VERSION = 1
SYNTHETIC_ROOT = "swarmpose_root"
"""Name of the bone added above a skin that has several root joints."""

_DTYPES = {gl.BYTE: "<i1", gl.UNSIGNED_BYTE: "<u1", gl.SHORT: "<i2", gl.UNSIGNED_SHORT: "<u2",
           gl.UNSIGNED_INT: "<u4", gl.FLOAT: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_NORMALIZER = {gl.BYTE: 127.0, gl.UNSIGNED_BYTE: 255.0, gl.SHORT: 32767.0, gl.UNSIGNED_SHORT: 65535.0}


# ---------------------------------------------------------------------------- export
def _affine_inverse(m: np.ndarray) -> np.ndarray:
    """Inverses (..., 4, 4) of affine matrices with an exact [0, 0, 0, 1] bottom row."""
    out = np.zeros_like(m, dtype=np.float64)
    inv = np.linalg.inv(m[..., :3, :3])
    out[..., :3, :3] = inv
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", inv, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def _node_transform(name: str, m: np.ndarray, children: list[int]) -> gl.Node:
    """A node with local matrix ``m`` (4, 4): TRS when it decomposes, else a raw matrix."""
    scale = np.linalg.norm(m[:3, :3], axis=0)
    rot = m[:3, :3] / np.where(scale > 0, scale, 1.0)
    if np.all(scale > 1e-12) and np.linalg.det(rot) > 0 and np.allclose(rot.T @ rot, np.eye(3), atol=1e-6):
        w, x, y, z = matrix_to_quaternion(rot)
        return gl.Node(name=name, children=children, translation=m[:3, 3].tolist(),
                       rotation=[float(x), float(y), float(z), float(w)],
                       scale=None if np.allclose(scale, 1.0, atol=1e-9) else scale.tolist())
    return gl.Node(name=name, children=children, matrix=m.T.reshape(-1).tolist())


def _vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals (V, 3); +Y for vertices in no triangle."""
    tri = vertices[triangles]
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.where(length > 1e-20, normals / np.where(length > 0, length, 1.0), [0.0, 1.0, 0.0])


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _extras(body: SkinnedBody) -> dict:
    """The swarmpose extras: everything a SkinnedBody has that glTF has no place for.

    ``metadata`` is a JSON string because pygltflib drops empty values from the JSON it
    writes, which would not round-trip ``{"note": ""}`` or ``{"tags": []}``.
    """
    try:
        metadata = json.dumps(body.metadata, default=_json_default, allow_nan=False)
    except (TypeError, ValueError) as err:
        raise OutputError(f"{body.name}: metadata cannot be written to glTF ({err}); keep it JSON-serialisable") \
            from err
    return {
        "format": FORMAT_NAME, "version": FORMAT_VERSION, "name": body.name,
        "bone_joint": [JOINT_NAMES[j] if j >= 0 else None for j in np.asarray(body.bone_joint, int)],
        "bone_fraction": [float(f) for f in body.bone_fraction],
        "points": [{"name": n, "bone": int(b), "rest": [float(c) for c in p]}
                   for n, b, p in zip(body.point_names, body.point_bones, body.point_rest)],
        "metadata": metadata,
    }


def save_glb(body: SkinnedBody, path) -> Path:
    """Write ``body`` as a skinned glTF 2.0 file and return its path.

    ``.gltf`` writes JSON with the buffer embedded as a data URI; any other suffix writes
    binary GLB. Positions are float32 metres in the body frame (= glTF frame).
    """
    path = Path(path)
    blob = bytearray()
    gltf = gl.GLTF2(asset=gl.Asset(generator="swarmpose", version="2.0"), scene=0)

    def add(array: np.ndarray, component: int, kind: str, target: int | None = None, bounds: bool = False) -> int:
        data = np.ascontiguousarray(array, dtype=_DTYPES[component]).tobytes()
        gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data)
        blob.extend(b"\0" * (-len(blob) % 4))
        acc = gl.Accessor(bufferView=len(gltf.bufferViews) - 1, componentType=component, count=len(array), type=kind)
        if bounds:
            acc.min = [float(c) for c in array.min(axis=0)]
            acc.max = [float(c) for c in array.max(axis=0)]
        gltf.accessors.append(acc)
        return len(gltf.accessors) - 1

    vertices = np.asarray(body.vertices, dtype=np.float64)
    triangles = np.asarray(body.triangles, dtype=np.int64)
    attributes = gl.Attributes(
        POSITION=add(vertices.astype(np.float32), gl.FLOAT, gl.VEC3, gl.ARRAY_BUFFER, bounds=True),
        NORMAL=add(_vertex_normals(vertices, triangles).astype(np.float32), gl.FLOAT, gl.VEC3, gl.ARRAY_BUFFER),
        JOINTS_0=add(np.asarray(body.skin_indices).astype(np.uint16), gl.UNSIGNED_SHORT, gl.VEC4, gl.ARRAY_BUFFER),
        WEIGHTS_0=add(np.asarray(body.skin_weights, dtype=np.float32), gl.FLOAT, gl.VEC4, gl.ARRAY_BUFFER),
    )
    indices = add(triangles.reshape(-1).astype(np.uint32), gl.UNSIGNED_INT, gl.SCALAR, gl.ELEMENT_ARRAY_BUFFER)
    binds = np.asarray(body.bind_matrices, dtype=np.float64)
    inverse = _affine_inverse(binds).transpose(0, 2, 1).reshape(-1, 16)  # column-major
    ibm = add(inverse.astype(np.float32), gl.FLOAT, gl.MAT4)

    parents = np.asarray(body.bone_parents, dtype=np.int64)
    gltf.meshes.append(gl.Mesh(name=body.name, primitives=[gl.Primitive(attributes=attributes, indices=indices,
                                                                        mode=gl.TRIANGLES)]))
    gltf.nodes.append(gl.Node(name=body.name, mesh=0, skin=0))
    for b, name in enumerate(body.bone_names):
        local = binds[b] if parents[b] < 0 else _affine_inverse(binds[parents[b]]) @ binds[b]
        gltf.nodes.append(_node_transform(name, local, [1 + int(c) for c in np.flatnonzero(parents == b)]))
    gltf.skins.append(gl.Skin(name=body.name, inverseBindMatrices=ibm, skeleton=1,
                              joints=list(range(1, 1 + len(body.bone_names))), extras={EXTRAS_KEY: _extras(body)}))
    gltf.scenes.append(gl.Scene(name=body.name, nodes=[0] + [1 + int(r) for r in np.flatnonzero(parents < 0)]))
    buffer = gl.Buffer(byteLength=len(blob))
    gltf.buffers.append(buffer)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() == ".gltf":
            buffer.uri = gl.DATA_URI_HEADER + base64.b64encode(bytes(blob)).decode("ascii")
            gltf.save_json(str(path))
        else:
            gltf.set_binary_blob(bytes(blob))
            gltf.save_binary(str(path))
    except OSError as err:
        raise OutputError(f"cannot write {path}: {err.strerror or err}; check the folder exists and is writable") \
            from err
    return path


# ---------------------------------------------------------------------------- reading
def _open(path: Path) -> gl.GLTF2:
    """Parse a .glb or .gltf file (judged by its first bytes, not its suffix)."""
    if not path.is_file():
        raise AssetError(f"{path}: no such file; give the path of a .glb or .gltf body model")
    with path.open("rb") as f:
        head = f.read(4)
    try:
        gltf = gl.GLTF2.load_binary(str(path)) if head == b"glTF" else gl.GLTF2.load_json(str(path))
    except Exception as err:  # pygltflib raises whatever its parser hits
        raise AssetError(f"{path}: not a glTF 2.0 file ({type(err).__name__}); export it as .glb or .gltf") from err
    if gltf is None or not isinstance(gltf.nodes, list):
        raise AssetError(f"{path}: not a glTF 2.0 file; export it as .glb or .gltf")
    version = str(getattr(gltf.asset, "version", "") or "")
    if not version.startswith("2."):
        raise AssetError(f"{path}: glTF version {version or '?'} is not supported; re-export as glTF 2.0")
    return gltf


class _Reader:
    """Typed access to the accessors of one parsed file."""

    def __init__(self, gltf: gl.GLTF2, path: Path) -> None:
        self.gltf, self.path = gltf, path
        self._buffers: dict[int, bytes] = {}

    def _buffer(self, index: int) -> bytes:
        if index not in self._buffers:
            with warnings.catch_warnings():  # pygltflib warns, then returns None; we raise instead
                warnings.simplefilter("ignore", UserWarning)
                data = self.gltf.get_data_from_buffer_uri(self.gltf.buffers[index].uri)
            if data is None:
                raise AssetError(f"{self.path}: buffer {index} cannot be read; keep its .bin next to the .gltf "
                                 "or export a self-contained .glb")
            self._buffers[index] = bytes(data)
        return self._buffers[index]

    def _view(self, view: int, offset: int, dtype: np.dtype, count: int, width: int) -> np.ndarray:
        bv = self.gltf.bufferViews[view]
        data = self._buffer(bv.buffer)
        start = (bv.byteOffset or 0) + (offset or 0)
        element = dtype.itemsize * width
        stride = bv.byteStride or element
        end = (bv.byteOffset or 0) + bv.byteLength
        if count and (start + stride * (count - 1) + element > min(end, len(data))):
            raise AssetError(f"{self.path}: buffer view {view} is shorter than its accessor; the file is truncated")
        return np.ndarray((count, width), dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize)).copy()

    def read(self, index: int | None, what: str) -> np.ndarray:
        """Accessor ``index`` as (count, width); normalised integers become floats in [0, 1]."""
        if index is None or not 0 <= index < len(self.gltf.accessors):
            raise AssetError(f"{self.path}: the skinned mesh has no valid {what} accessor; re-export the model")
        acc = self.gltf.accessors[index]
        if acc.componentType not in _DTYPES or acc.type not in _WIDTH:
            raise AssetError(f"{self.path}: {what} accessor has invalid type {acc.componentType}/{acc.type}; "
                             "re-export the model")
        dtype, width = np.dtype(_DTYPES[acc.componentType]), _WIDTH[acc.type]
        if acc.bufferView is None:
            out = np.zeros((acc.count, width), dtype)
        else:
            out = self._view(acc.bufferView, acc.byteOffset, dtype, acc.count, width)
        if acc.sparse is not None and acc.sparse.count:
            sp = acc.sparse
            where = self._view(sp.indices.bufferView, sp.indices.byteOffset,
                               np.dtype(_DTYPES[sp.indices.componentType]), sp.count, 1)[:, 0]
            out[where.astype(np.int64)] = self._view(sp.values.bufferView, sp.values.byteOffset, dtype, sp.count, width)
        if acc.normalized and acc.componentType in _NORMALIZER:
            return np.maximum(out / _NORMALIZER[acc.componentType], -1.0)
        return out


def _local_matrix(node: gl.Node) -> np.ndarray:
    """A node's local transform (4, 4) from ``matrix`` or T @ R @ S."""
    if node.matrix:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    x, y, z, w = node.rotation or (0.0, 0.0, 0.0, 1.0)
    m[:3, :3] = quaternion_to_matrix([w, x, y, z]) * np.asarray(node.scale or (1.0, 1.0, 1.0))
    m[:3, 3] = node.translation or (0.0, 0.0, 0.0)
    return m


def _node_parents(gltf: gl.GLTF2) -> dict[int, int]:
    return {c: i for i, node in enumerate(gltf.nodes) for c in (node.children or [])}


def _world_matrix(gltf: gl.GLTF2, parents: dict[int, int], node: int) -> np.ndarray:
    m, seen = _local_matrix(gltf.nodes[node]), {node}
    while (node := parents.get(node)) is not None and node not in seen:
        seen.add(node)
        m = _local_matrix(gltf.nodes[node]) @ m
    return m


def _skinned_primitive(gltf: gl.GLTF2, path: Path) -> tuple[gl.Node, gl.Primitive]:
    """The first node with a mesh and a skin, and that mesh's first triangle primitive."""
    if not gltf.meshes:
        raise AssetError(f"{path}: the file has no mesh; export the body mesh together with its armature")
    for node in gltf.nodes:
        if node.mesh is None or node.skin is None or not 0 <= node.skin < len(gltf.skins):
            continue
        prims = gltf.meshes[node.mesh].primitives
        for prim in prims:
            attrs = prim.attributes
            if prim.mode in (None, gl.TRIANGLES) and getattr(attrs, "JOINTS_0", None) is not None:
                if getattr(attrs, "WEIGHTS_0", None) is None:
                    raise AssetError(f"{path}: the skinned mesh has JOINTS_0 but no WEIGHTS_0; "
                                     "re-export it with its skin weights")
                return node, prim
        if prims and all(p.mode not in (None, gl.TRIANGLES) for p in prims):
            raise AssetError(f"{path}: the skinned mesh is not made of triangles (mode {prims[0].mode}); "
                             "triangulate it before export")
    raise AssetError(f"{path}: no skinned mesh (a mesh node with a skin and JOINTS_0/WEIGHTS_0); "
                     "export the mesh with its armature and skin weights")


def _skin_weights(reader: _Reader, prim: gl.Primitive, remap: np.ndarray, n_bones: int, path: Path):
    """Skin (V, 4) indices int32 / weights float32 from every JOINTS_n/WEIGHTS_n set."""
    joints, weights, k = [], [], 0
    while (getattr(prim.attributes, f"JOINTS_{k}", None) is not None
           and getattr(prim.attributes, f"WEIGHTS_{k}", None) is not None):
        joints.append(reader.read(getattr(prim.attributes, f"JOINTS_{k}"), f"JOINTS_{k}").astype(np.int64))
        weights.append(reader.read(getattr(prim.attributes, f"WEIGHTS_{k}"), f"WEIGHTS_{k}").astype(np.float64))
        k += 1
    idx, w = np.concatenate(joints, axis=1), np.concatenate(weights, axis=1)
    if idx.min() < 0 or idx.max() >= len(remap):
        raise AssetError(f"{path}: JOINTS_0 refers to joint {idx.max()} but the skin has {len(remap)} joints")
    idx = remap[idx]
    if idx.shape[1] > MAX_INFLUENCES:
        dense = np.zeros((len(idx), n_bones))
        np.add.at(dense, (np.arange(len(idx))[:, None].repeat(idx.shape[1], 1), idx), w)
        return sparse_skin(dense, len(idx))
    total = w.sum(axis=1, keepdims=True)
    if np.any(total <= 0):
        raise AssetError(f"{path}: vertex {int(np.flatnonzero(total[:, 0] <= 0)[0])} has no skin weight; "
                         "weight every vertex to at least one bone")
    w = w / total
    pad = ((0, 0), (0, MAX_INFLUENCES - idx.shape[1]))
    return np.pad(np.where(w > 0, idx, 0), pad).astype(np.int32), np.pad(w, pad).astype(np.float32)


# ---------------------------------------------------------------------------- foreign rigs
_CENTRE_NAMES = {
    "pelvis": ("hips", "hip", "pelvis"),
    "spine": ("lowerback", "spine", "spine1", "spine2", "spine3", "spine01", "spine02", "spine03",
              "spinelower", "spineupper", "chest", "upperchest", "abdomen"),
    "neck": ("neck", "neck1", "neck2", "neck01", "neck02"),
    "head": ("head",),
}
_SIDED_NAMES = {  # {s} = left/right, {c} = l/r
    "clavicle": ("{s}shoulder", "{s}clavicle", "{s}collar", "clavicle{c}", "{c}clavicle", "{c}collar"),
    "upper_arm": ("{s}arm", "{s}upperarm", "upperarm{c}", "{c}upperarm", "{c}shldr"),
    "forearm": ("{s}forearm", "{s}lowerarm", "lowerarm{c}", "{c}forearm"),
    "hand": ("{s}hand", "hand{c}", "{c}hand"),
    "hip_joint": ("{c}hipjoint",),
    "thigh": ("{s}upleg", "{s}upperleg", "{s}thigh", "thigh{c}", "{c}thigh"),
    "shin": ("{s}leg", "{s}lowerleg", "{s}shin", "calf{c}", "{c}calf", "{c}shin"),
    "foot": ("{s}foot", "foot{c}", "{c}foot"),
    "toe": ("{s}toebase", "{s}toes", "{s}toe", "ball{c}", "{c}toe0"),
    "eye": ("{s}eye", "eye{c}"),
}
BONE_ROLES: dict[str, str] = {
    **{n: role for role, names in _CENTRE_NAMES.items() for n in names},
    **{t.format(s=side, c=side[0]): f"{side}_{role}" for role, templates in _SIDED_NAMES.items()
       for t in templates for side in ("left", "right")},
}
"""Canonical bone name (see :func:`canonical_bone_name`) -> role; unmapped bones are rigid."""

REQUIRED_ROLES = ("pelvis", "neck", "head") + tuple(
    f"{side}_{role}" for side in ("left", "right")
    for role in ("clavicle", "upper_arm", "forearm", "hand", "thigh", "shin", "foot"))
_ROLE_JOINT = {"clavicle": "collar", "upper_arm": "shoulder", "forearm": "elbow", "thigh": "hip", "shin": "knee",
               "foot": "ankle"}
_ROLE_POINT = {"clavicle": "clavicle", "upper_arm": "shoulder", "forearm": "elbow", "hand": "wrist", "thigh": "hip",
               "shin": "knee", "foot": "ankle"}
_FACIAL = ("eye", "jaw", "ear", "tongue", "teeth", "lip", "brow", "nose")


def canonical_bone_name(name: str) -> str:
    """``"mixamorig:LeftUpLeg"`` -> ``"leftupleg"``: namespace and rig prefix gone, lower case, alphanumerics."""
    base = re.split(r"[:|]", name)[-1].lower()
    base = re.sub(r"^(mixamorig\d*|bip\d*)", "", base)
    return re.sub(r"[^a-z0-9]", "", base)


def _map_foreign(names: list[str], parents: np.ndarray, heads: np.ndarray, path: Path):
    """bone_joint (B,), bone_fraction (B,) and {point: bone} anchors of a rig known by its bone names."""
    roles: dict[str, int] = {}
    necks: set[int] = set()
    for b, name in enumerate(names):
        role = BONE_ROLES.get(canonical_bone_name(name))
        if role == "neck":
            necks.add(b)
        if role is not None and role not in roles:
            roles[role] = b
    missing = [r for r in REQUIRED_ROLES if r not in roles]
    if missing:
        raise AssetError(f"{path}: cannot map the rig, no bone for {missing}; bones found: {list(names)} "
                         "(rename the bones to Mixamo, CMU or swarmpose names)")
    left, right = heads[roles["left_upper_arm"]], heads[roles["right_upper_arm"]]
    across = left - right
    if across[0] <= 0.5 * np.linalg.norm(across):
        raise AssetError(f"{path}: the model does not face +Z: its left shoulder is at {np.round(left, 3).tolist()} "
                         f"and its right at {np.round(right, 3).tolist()}, but glTF/swarmpose want the character's "
                         "left on +X, Y up, facing +Z; rotate it so before export")
    if heads[roles["head"], 1] <= heads[roles["pelvis"], 1]:
        raise AssetError(f"{path}: the head bone is not above the pelvis; glTF is Y up, re-export with +Y up")

    chain, b = [], int(parents[roles["head"]])
    while b >= 0 and b != roles["pelvis"]:
        chain.append(b)
        b = int(parents[b])
    chain.reverse()
    first_neck = next((i for i, c in enumerate(chain) if c in necks), None)
    if b != roles["pelvis"] or first_neck is None or first_neck == 0:
        raise AssetError(f"{path}: no pelvis -> spine -> neck -> head chain in the rig (between the pelvis and the "
                         f"head: {[names[c] for c in chain]}); the spine needs at least one bone and a neck bone")
    bone_joint = np.full(len(names), -1, dtype=np.int64)
    bone_fraction = np.ones(len(names))
    for joint, bones in (("spine", chain[:first_neck]), ("neck", chain[first_neck:])):
        bone_joint[bones] = JOINT_INDEX[joint]
        bone_fraction[bones] = 1.0 / len(bones)
    anchors = {"spine": chain[0], "neck": chain[first_neck], "head": roles["head"], "mid_hip": roles["pelvis"]}
    for side in ("left", "right"):
        for role, point in _ROLE_POINT.items():
            bone = roles[f"{side}_{role}"]
            anchors[f"{side}_{point}"] = bone
            if role in _ROLE_JOINT:
                bone_joint[bone] = JOINT_INDEX[f"{side}_{_ROLE_JOINT[role]}"]
    eyes = (roles.get("left_eye"), roles.get("right_eye"))
    return bone_joint, bone_fraction, anchors, eyes


def _foreign_points(names, parents, heads, vertices, anchors, eyes):
    """Rest positions and carrier bones of every named point of a foreign rig."""
    points = {p: heads[b] for p, b in anchors.items()}
    bones = dict(anchors)
    points["mid_hip"] = 0.5 * (heads[anchors["left_hip"]] + heads[anchors["right_hip"]])
    h = anchors["head"]
    crown_children = [c for c in np.flatnonzero(parents == h)
                      if heads[c, 1] > heads[h, 1] + 0.05 and not any(f in names[c].lower() for f in _FACIAL)]
    if crown_children:
        crown = heads[max(crown_children, key=lambda c: heads[c, 1])]
    else:
        above = (np.hypot(vertices[:, 0] - heads[h, 0], vertices[:, 2] - heads[h, 2]) < 0.15) \
            & (vertices[:, 1] > heads[h, 1])
        if not np.any(above):
            raise AssetError("no mesh above the head bone; cannot place the head centre")
        crown = np.array([heads[h, 0], vertices[above, 1].max(), heads[h, 2]])
    points["head"] = 0.5 * (heads[h] + crown)
    eye_pair = None if None in eyes else (heads[eyes[0]], heads[eyes[1]])
    for name, p in face_landmarks(vertices, points["head"], points["neck"], eye_pair).items():
        points[name], bones[name] = p, h
    for name, p in foot_landmarks(vertices, points["left_ankle"], points["right_ankle"]).items():
        points[name], bones[name] = p, anchors[f"{name.split('_')[0]}_ankle"]
    return (tuple(POINT_NAMES), np.array([bones[p] for p in POINT_NAMES], dtype=np.int64),
            np.array([points[p] for p in POINT_NAMES], dtype=np.float64))


# ---------------------------------------------------------------------------- import
def _extras_of(gltf: gl.GLTF2, skin: gl.Skin) -> dict | None:
    for holder in [skin, *(gltf.scenes or [])]:
        extras = getattr(holder, "extras", None) or {}
        if isinstance(extras.get(EXTRAS_KEY), dict):
            return extras[EXTRAS_KEY]
    return None


def _restore_extras(ext: dict, n_joints: int, remap: np.ndarray, n_bones: int, path: Path):
    """bone_joint, bone_fraction, point names/bones/rest and metadata from swarmpose extras."""
    if ext.get("format") != FORMAT_NAME or int(ext.get("version", 0)) > FORMAT_VERSION:
        raise AssetError(f"{path}: swarmpose extras of format {ext.get('format')!r} v{ext.get('version')} are "
                         f"not readable by this version (v{FORMAT_VERSION}); upgrade swarmpose")
    joints, fractions, points = ext.get("bone_joint", []), ext.get("bone_fraction", []), ext.get("points", [])
    if len(joints) != n_joints or len(fractions) != n_joints:
        raise AssetError(f"{path}: swarmpose extras describe {len(joints)} bones but the skin has {n_joints}; "
                         "the file was edited, drop the extras to map it by bone names")
    bone_joint = np.full(n_bones, -1, dtype=np.int64)
    bone_fraction = np.ones(n_bones)
    try:
        bone_joint[remap] = [-1 if j is None else JOINT_INDEX[j] for j in joints]
    except KeyError as err:
        raise AssetError(f"{path}: unknown tracking joint {err} in the swarmpose extras") from err
    bone_fraction[remap] = fractions
    names = tuple(str(p["name"]) for p in points)
    bones = remap[np.array([int(p["bone"]) for p in points], dtype=np.int64)]
    rest = np.array([p["rest"] for p in points], dtype=np.float64).reshape(-1, 3)
    metadata = json.loads(ext.get("metadata") or "{}")
    return bone_joint, bone_fraction, names, bones, rest, metadata


def _joint_hierarchy(gltf: gl.GLTF2, node_parents: dict[int, int], joints: list[int], path: Path):
    """Skin-joint parents (J,) (-1 = root), a parents-first order (J,), the main root, several roots?

    A joint's parent is its nearest ancestor node that is also a skin joint. The order is
    topological, keeping the file's order where it already is; the main root is the one
    with the largest subtree.
    """
    slot = {n: j for j, n in enumerate(joints)}
    joint_parent = np.full(len(joints), -1, dtype=np.int64)
    for j, n in enumerate(joints):
        up, steps = node_parents.get(n), 0
        while up is not None and up not in slot and steps <= len(gltf.nodes):
            up, steps = node_parents.get(up), steps + 1
        joint_parent[j] = slot.get(up, -1) if up is not None else -1
    roots, children = [], [[] for _ in joints]
    for j, p in enumerate(joint_parent):
        (children[p] if p >= 0 else roots).append(j)
    order, heap = [], list(roots)
    heapq.heapify(heap)
    while heap:
        order.append(j := heapq.heappop(heap))
        for c in children[j]:
            heapq.heappush(heap, c)
    if len(order) != len(joints):
        raise AssetError(f"{path}: the skin's joint hierarchy has a cycle; re-export the armature")
    size = np.ones(len(joints), dtype=np.int64)
    for j in reversed(order):
        if joint_parent[j] >= 0:
            size[joint_parent[j]] += size[j]
    return joint_parent, np.array(order), max(roots, key=lambda r: (size[r], -r)), len(roots) > 1


def load_glb(path) -> SkinnedBody:
    """Load a skinned body from a .glb (or .gltf with embedded or adjacent buffers).

    Reads the first skinned triangle primitive (other primitives and meshes are ignored);
    bones are the skin's joints reordered parents-first (a synthetic root is added above
    several roots). ``bind_matrices`` = ``C @ inv(IBM)`` (B, 4, 4) and vertices ``C @ v``
    (V, 3) m, where ``C`` = the root joint's world rest transform times its IBM (= the mesh
    node's world transform for a conventional export; identity when the IBMs already hold
    world space), so the body appears as glTF viewers show it. More than 4 influences keep
    the 4 largest. Swarmpose extras restore the tracking mapping exactly (their points are
    in the file's mesh space, mapped by ``C`` too); otherwise bones are mapped by name
    (:data:`BONE_ROLES`). Everything is then shifted so the root bone's head is at the
    origin. Raises :class:`AssetError`.
    """
    path = Path(path)
    gltf = _open(path)
    node, prim = _skinned_primitive(gltf, path)
    skin = gltf.skins[node.skin]
    reader = _Reader(gltf, path)
    joints = list(skin.joints or [])
    if not joints or skin.inverseBindMatrices is None:
        raise AssetError(f"{path}: the skin has no joints or no inverseBindMatrices; re-export with the armature")
    ibm = reader.read(skin.inverseBindMatrices, "inverseBindMatrices")
    ibm = ibm.reshape(-1, 4, 4).transpose(0, 2, 1) if ibm.shape[1] == 16 else ibm[:0].reshape(0, 4, 4)
    if len(ibm) != len(joints):
        raise AssetError(f"{path}: {len(ibm)} inverse bind matrices for {len(joints)} joints; re-export the skin")

    node_parents = _node_parents(gltf)
    joint_parent, order, main_root, synthetic = _joint_hierarchy(gltf, node_parents, joints, path)
    remap = np.empty(len(joints), dtype=np.int64)
    remap[order] = np.arange(len(order)) + int(synthetic)

    to_world = _world_matrix(gltf, node_parents, joints[main_root]) @ ibm[main_root]
    if np.allclose(to_world, np.eye(4), atol=1e-6):
        to_world = np.eye(4)
    if abs(np.linalg.det(to_world[:3, :3])) < 1e-12:
        raise AssetError(f"{path}: the root joint's transform is degenerate (zero scale); fix the armature")
    vertices = reader.read(prim.attributes.POSITION, "POSITION").astype(np.float64) @ to_world[:3, :3].T \
        + to_world[:3, 3]
    if prim.indices is None:
        triangles = np.arange(len(vertices) - len(vertices) % 3).reshape(-1, 3)
    else:
        triangles = reader.read(prim.indices, "indices").astype(np.int64).reshape(-1, 3)
    names = [gltf.nodes[joints[j]].name or f"joint{j}" for j in order]
    parents = np.array([-1 if joint_parent[j] < 0 else remap[joint_parent[j]] for j in order], dtype=np.int64)
    binds = to_world @ _affine_inverse(ibm[order].astype(np.float64))
    if synthetic:
        root_bind = np.eye(4)
        root_bind[:3, 3] = binds[remap[main_root] - 1, :3, 3]
        names, parents, binds = [SYNTHETIC_ROOT] + names, np.concatenate([[-1], np.maximum(parents, 0)]), \
            np.concatenate([root_bind[None], binds])
    skin_indices, skin_weights = _skin_weights(reader, prim, remap, len(names), path)
    heads = binds[:, :3, 3].copy()
    shift = heads[0].copy() if np.linalg.norm(heads[0]) > 1e-9 else np.zeros(3)
    vertices, heads = vertices - shift, heads - shift
    binds[:, :3, 3] -= shift

    ext = _extras_of(gltf, skin)
    if ext is not None:
        bone_joint, bone_fraction, point_names, point_bones, point_rest, metadata = _restore_extras(
            ext, len(joints), remap, len(names), path)
        point_rest = point_rest @ to_world[:3, :3].T + to_world[:3, 3] - shift
        name = str(ext.get("name") or path.stem)
    else:
        height = float(np.ptp(vertices[:, 1])) if len(vertices) else 0.0
        if not 0.3 <= height <= 3.0:
            raise AssetError(f"{path}: the model is {height:.3g} units tall; glTF units are metres, rescale it "
                             "(e.g. a centimetre rig needs scale 0.01) before export")
        bone_joint, bone_fraction, anchors, eyes = _map_foreign(names, parents, heads, path)
        try:
            point_names, point_bones, point_rest = _foreign_points(names, parents, heads, vertices, anchors, eyes)
        except AssetError as err:
            raise AssetError(f"{path}: {err}; check the mesh is the whole body in metres") from err
        metadata = {"source": str(path), "rig": "mapped by bone names"}
        name = path.stem
    try:
        return SkinnedBody(
            name=name, vertices=vertices, triangles=triangles.astype(np.int32), skin_indices=skin_indices,
            skin_weights=skin_weights, bone_names=tuple(names), bone_parents=parents, bone_heads=heads,
            bind_matrices=binds, bone_joint=bone_joint, bone_fraction=bone_fraction, point_names=point_names,
            point_bones=point_bones, point_rest=point_rest, metadata=metadata,
        )
    except ShapeError as err:
        raise AssetError(f"{path}: inconsistent skinned mesh ({err}); re-export the model") from err
