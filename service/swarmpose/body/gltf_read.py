"""glTF 2.0 / GLB import of a :class:`SkinnedBody` (through pygltflib).

:func:`load_glb` reads the first skinned triangle primitive of a .glb or .gltf file and
restores swarmpose's own ``skin.extras`` exactly (see :mod:`swarmpose.body.gltf_write`),
or maps a foreign rig onto the tracking skeleton by bone name
(:mod:`swarmpose.body.gltf_rig`). The body frame (X = the subject's left, Y up,
Z forward, metres) *is* glTF's frame, so no axis conversion happens.
"""

from __future__ import annotations

import heapq
import json
import warnings
from pathlib import Path

import numpy as np
import pygltflib as gl

from swarmpose.body.gltf_format import (
    COMPONENT_DTYPES,
    EXTRAS_KEY,
    FORMAT_NAME,
    FORMAT_VERSION,
    NORMALIZERS,
    SYNTHETIC_ROOT,
    TYPE_WIDTHS,
    affine_inverse,
)
from swarmpose.body.gltf_rig import foreign_points, map_foreign_rig
from swarmpose.body.kinematics import quaternion_to_matrix
from swarmpose.body.skeleton import JOINT_INDEX
from swarmpose.body.skinned import MAX_INFLUENCES, SkinnedBody, sparse_skin
from swarmpose.core.errors import AssetError, ShapeError


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
        if acc.componentType not in COMPONENT_DTYPES or acc.type not in TYPE_WIDTHS:
            raise AssetError(f"{self.path}: {what} accessor has invalid type {acc.componentType}/{acc.type}; "
                             "re-export the model")
        dtype, width = np.dtype(COMPONENT_DTYPES[acc.componentType]), TYPE_WIDTHS[acc.type]
        if acc.bufferView is None:
            out = np.zeros((acc.count, width), dtype)
        else:
            out = self._view(acc.bufferView, acc.byteOffset, dtype, acc.count, width)
        if acc.sparse is not None and acc.sparse.count:
            sp = acc.sparse
            where = self._view(sp.indices.bufferView, sp.indices.byteOffset,
                               np.dtype(COMPONENT_DTYPES[sp.indices.componentType]), sp.count, 1)[:, 0]
            out[where.astype(np.int64)] = self._view(sp.values.bufferView, sp.values.byteOffset, dtype, sp.count, width)
        if acc.normalized and acc.componentType in NORMALIZERS:
            return np.maximum(out / NORMALIZERS[acc.componentType], -1.0)
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


def _extras_of(gltf: gl.GLTF2, skin: gl.Skin) -> dict | None:
    for holder in [skin, *(gltf.scenes or [])]:
        extras = getattr(holder, "extras", None) or {}
        if isinstance(extras.get(EXTRAS_KEY), dict):
            return extras[EXTRAS_KEY]
    return None


def _exact(reader: _Reader, ext: dict | None, name: str, read: np.ndarray) -> np.ndarray:
    """The float64 copy of ``read`` (any shape) that swarmpose wrote beside the float32 accessors
    (the extras' ``exact``, see :mod:`swarmpose.body.gltf_write`), in ``read``'s dtype, when all of it
    lies within 1e-6 of what was read; else ``read`` (all or nothing). A file edited by another tool
    keeps its accessors and loses the match, so its edits win; a file written before the exact copies
    existed has none and gives ``read``."""
    view = ((ext or {}).get("exact") or {}).get(name)
    if not isinstance(view, int) or not 0 <= view < len(reader.gltf.bufferViews) \
            or reader.gltf.bufferViews[view].byteLength != read.size * 8:
        return read
    exact = reader._view(view, 0, np.dtype("<f8"), read.size, 1).reshape(read.shape)
    return exact.astype(read.dtype) if np.abs(exact - read).max(initial=0.0) <= 1e-6 else read


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
    (:data:`swarmpose.body.gltf_rig.BONE_ROLES`). Everything is then shifted so the root bone's head is at the
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
    binds = to_world @ affine_inverse(ibm[order].astype(np.float64))
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
    vertices = _exact(reader, ext, "positions", vertices)
    binds = _exact(reader, ext, "bind_matrices", binds)
    skin_weights = _exact(reader, ext, "skin_weights", skin_weights)
    heads = binds[:, :3, 3].copy()
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
        bone_joint, bone_fraction, anchors, eyes = map_foreign_rig(names, parents, heads, path)
        try:
            point_names, point_bones, point_rest = foreign_points(names, parents, heads, vertices, anchors, eyes)
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
