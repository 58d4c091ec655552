"""``SkinnedBody``: one skinned, rigged human body model, whatever it was loaded from.

Shapes and units: ``V`` vertices, ``F`` triangles, ``B`` bones, ``K`` = 4 influences,
``N`` named points; positions in metres in the body frame (X left, Y up, Z forward; see
:mod:`swarmpose.body.skeleton`), the root bone's head at the origin.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace
from functools import cached_property
from importlib.metadata import version
from pathlib import Path

import numpy as np

from swarmpose.body.joint_angles import rest_angles
from swarmpose.body.kinematics import (
    Rig,
    canonical_rotations,
    dual_quaternion_skinning,
    linear_blend_skinning,
    skinning_transforms,
    transform_points,
)
from swarmpose.body.skeleton import JOINT_INDEX, POINT_NAMES, TRACKING_JOINTS
from swarmpose.core.cache import cache_key, cached_arrays
from swarmpose.core.errors import AssetError, ConfigError, ShapeError, check_shape
from swarmpose.core.open3d_import import open3d

MAX_INFLUENCES = 4
MIN_LOD_TRIANGLES = 100
SKINNING_METHODS = ("lbs", "dqs")
POSE_MEMO = 16
"""Single poses whose bone transforms a body remembers (:meth:`SkinnedBody.transforms`): one tracked
frame poses its track's last pose, its prediction and its best fit several times over."""


def sparse_skin(dense_or_pairs, n_vertices: int, k: int = MAX_INFLUENCES) -> tuple[np.ndarray, np.ndarray]:
    """Keep each vertex's ``k`` largest bone weights and renormalise them to sum to 1.

    Accepts a dense (V, B) weight matrix. Returns indices (V, k) int32 and weights
    (V, k) float32; unused slots point at bone 0 with weight 0. Vertices with no weight
    at all raise :class:`AssetError`.
    """
    dense = np.asarray(dense_or_pairs, dtype=np.float64)
    check_shape("dense skin weights", dense, (n_vertices, None))
    kk = min(k, dense.shape[1])
    order = np.argsort(-dense, axis=1)[:, :kk]
    w = np.take_along_axis(dense, order, axis=1)
    total = w.sum(axis=1, keepdims=True)
    if np.any(total <= 0):
        bad = int(np.flatnonzero(total[:, 0] <= 0)[0])
        raise AssetError(f"vertex {bad} has no skin weight; every vertex needs at least one bone")
    w = w / total
    idx = np.where(w > 0, order, 0)
    if kk < k:
        idx = np.pad(idx, ((0, 0), (0, k - kk)))
        w = np.pad(w, ((0, 0), (0, k - kk)))
    return idx.astype(np.int32), w.astype(np.float32)


@dataclass(frozen=True, eq=False)
class SkinnedBody:
    """A skinned body with its mapping onto the 29-DOF tracking skeleton.

    vertices: (V, 3) rest positions, m. triangles: (F, 3) int32, counter-clockwise seen
    from outside. skin_indices / skin_weights: (V, 4) int32 / float32, weights sum to 1.
    bone_names: B names; bone_parents: (B,) int, -1 for the root (index 0), topological.
    bone_heads: (B, 3) rest pivots, m. bind_matrices: (B, 4, 4) rest bone-to-body
    transforms (for export; kinematics uses rest-relative rotations only).
    bone_joint: (B,) tracking-joint index driving each bone, -1 = rigid to its parent.
    bone_fraction: (B,) share of the joint's angles the bone takes (spines split).
    point_names / point_bones / point_rest: the named points (``POINT_NAMES``) with the
    bone that carries each and its rest position (N, 3).
    """

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    skin_indices: np.ndarray
    skin_weights: np.ndarray
    bone_names: tuple[str, ...]
    bone_parents: np.ndarray
    bone_heads: np.ndarray
    bind_matrices: np.ndarray
    bone_joint: np.ndarray
    bone_fraction: np.ndarray
    point_names: tuple[str, ...]
    point_bones: np.ndarray
    point_rest: np.ndarray
    metadata: dict = field(default_factory=dict)
    _memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        v, b, n = len(self.vertices), len(self.bone_names), len(self.point_names)
        if v < 4 or len(self.triangles) < 1:
            raise AssetError(f"{self.name}: a body needs a mesh; got {v} vertices and {len(self.triangles)} triangles")
        check_shape("vertices", self.vertices, (v, 3))
        check_shape("triangles", self.triangles, (None, 3))
        check_shape("skin_indices", self.skin_indices, (v, MAX_INFLUENCES))
        check_shape("skin_weights", self.skin_weights, (v, MAX_INFLUENCES))
        for name, arr, shape in (("bone_parents", self.bone_parents, (b,)), ("bone_heads", self.bone_heads, (b, 3)),
                                 ("bind_matrices", self.bind_matrices, (b, 4, 4)),
                                 ("bone_joint", self.bone_joint, (b,)), ("bone_fraction", self.bone_fraction, (b,)),
                                 ("point_bones", self.point_bones, (n,)), ("point_rest", self.point_rest, (n, 3))):
            check_shape(name, arr, shape)
        if len(self.triangles) and (self.triangles.min() < 0 or self.triangles.max() >= v):
            raise ShapeError(f"{self.name}: triangle indices out of range 0..{v - 1}")
        if self.skin_indices.min() < 0 or self.skin_indices.max() >= b:
            raise ShapeError(f"{self.name}: skin indices out of range 0..{b - 1}")
        if not np.all(np.isfinite(self.vertices)):
            raise ShapeError(f"{self.name}: vertices contain NaN or infinity")
        if not np.allclose(self.skin_weights.sum(axis=1), 1.0, atol=1e-4):
            raise ShapeError(f"{self.name}: skin weights must sum to 1 per vertex")
        missing = [p for p in POINT_NAMES if p not in self.point_names]
        if missing:
            raise AssetError(f"{self.name}: body lacks named points {missing}")
        for arr in (self.vertices, self.triangles, self.skin_indices, self.skin_weights, self.bone_parents,
                    self.bone_heads, self.bind_matrices, self.bone_joint, self.bone_fraction, self.point_bones,
                    self.point_rest):
            arr.setflags(write=False)  # bodies are cached and shared: nobody may edit them in place
        driven = {int(j) for j in self.bone_joint if j >= 0}
        if driven != set(range(len(TRACKING_JOINTS))):
            lacking = [TRACKING_JOINTS[j].name for j in range(len(TRACKING_JOINTS)) if j not in driven]
            raise AssetError(f"{self.name}: no bone is driven by tracking joints {lacking}")

    # ------------------------------------------------------------------ derived
    def point(self, name: str) -> np.ndarray:
        """Rest position (3,) of named point ``name``."""
        return self.point_rest[self.point_names.index(name)]

    def point_indices(self, names) -> np.ndarray:
        """Indices into the named points of ``names`` (iterable of str)."""
        return np.array([self.point_names.index(n) for n in names], dtype=np.int64)

    @cached_property
    def rest_angles(self) -> np.ndarray:
        """(29,) the joint angles of this body's rest pose (zero = the T-pose), rad; cached, since
        finding them takes scipy's rotations, whose import costs every start about half a second."""
        from swarmpose.body import joint_angles, skeleton

        key = cache_key(self.point_names, self.point_rest.tobytes(), version("scipy"),
                        sources=(Path(joint_angles.__file__), Path(skeleton.__file__)))
        return cached_arrays("rest_angles", key, lambda: {"angles": rest_angles(self.point)})["angles"]

    @cached_property
    def rig(self) -> Rig:
        """The arrays :func:`swarmpose.body.kinematics.forward_kinematics` needs."""
        frames = canonical_rotations(self.bone_parents, self.bone_joint, self.bone_fraction,
                                     np.eye(3)[None], self.rest_angles[None])[0]
        return Rig(self.bone_parents, self.bone_heads, self.bone_joint, self.bone_fraction, frames)

    def rest_pose(self, translation=(0.0, 0.0, 0.0), quaternion=(1.0, 0.0, 0.0, 0.0)) -> np.ndarray:
        """The (36,) pose that reproduces the rest mesh, moved and turned as given."""
        return np.concatenate([translation, quaternion, self.rest_angles])

    @property
    def height(self) -> float:
        """Standing height in the rest pose (vertical extent of the mesh), metres."""
        return float(np.ptp(self.vertices[:, 1]))

    @property
    def floor_offset(self) -> float:
        """Height of the root joint above the soles in the rest pose, metres."""
        return float(-self.vertices[:, 1].min())

    def bones_of_joint(self, joint: str) -> list[int]:
        """The bones that tracking joint ``joint`` rotates."""
        return [int(b) for b in np.flatnonzero(self.bone_joint == JOINT_INDEX[joint])]

    # ------------------------------------------------------------------ posing
    def transforms(self, h: np.ndarray) -> np.ndarray:
        """Bone transforms (P, B, 3, 4) for poses ``h`` (P, 36), read-only.

        A single pose's are remembered, up to :data:`POSE_MEMO` of them, the oldest given up first (the
        body is immutable, so they stay right): a frame's steps pose the same few poses again and again."""
        h = np.atleast_2d(np.asarray(h, dtype=np.float64))
        key = h.tobytes() if h.shape[0] == 1 else None
        out = None if key is None else self._memo.get(key)
        if out is None:
            out = skinning_transforms(self.rig, h)
            out.setflags(write=False)
            if key is not None:
                self._remember(key, out)
        return out

    def _remember(self, key: bytes, transforms: np.ndarray) -> None:
        """Keep one pose's ``transforms``, giving up the oldest beyond :data:`POSE_MEMO` (several threads
        may pose one body: a race costs at most a result given up early)."""
        memo = self._memo
        memo[key] = transforms
        while len(memo) > POSE_MEMO:
            try:
                memo.pop(next(iter(memo)), None)
            except (RuntimeError, StopIteration):  # another thread changed it meanwhile
                break

    def pose(self, h: np.ndarray, skinning: str = "lbs") -> np.ndarray:
        """Posed vertices (P, V, 3) in the camera frame for poses (P, 36); ``skinning`` lbs|dqs."""
        return self.skin(self.transforms(h), skinning)

    def skin(self, transforms: np.ndarray, skinning: str = "lbs") -> np.ndarray:
        """Skinned vertices (P, V, 3) for bone transforms (P, B, 3, 4); ``skinning`` lbs|dqs."""
        if skinning not in SKINNING_METHODS:
            raise ValueError(f"skinning must be one of {SKINNING_METHODS}, got {skinning!r}")
        fn = linear_blend_skinning if skinning == "lbs" else dual_quaternion_skinning
        return fn(self.vertices, self.skin_indices, self.skin_weights, transforms)

    def posed_points(self, h: np.ndarray, names=None) -> np.ndarray:
        """Named points (P, N, 3) in the camera frame; ``names`` defaults to all point_names."""
        return self.points_at(self.transforms(h), names)

    def points_at(self, transforms: np.ndarray, names=None) -> np.ndarray:
        """Named points (P, N, 3) under bone ``transforms`` (P, B, 3, 4) (:meth:`transforms`, for a
        caller that needs them for more than the points); ``names`` defaults to all point_names."""
        idx = np.arange(len(self.point_names)) if names is None else self.point_indices(names)
        return transform_points(self.point_bones[idx], self.point_rest[idx], transforms)

    # ------------------------------------------------------------------ variants
    def tracking_lod(self, triangles: int = 1500) -> SkinnedBody:
        """This body decimated to about ``triangles`` triangles, skinning preserved.

        Quadric decimation (Open3D) moves vertices; each new vertex takes the skin weights
        of the nearest original vertex, and the named points and bones are unchanged. Kept in
        the user's cache (:mod:`swarmpose.core.cache`) under the mesh, its skin and this code, so
        that a later process loads it instead of decimating again.
        """
        if triangles < MIN_LOD_TRIANGLES:
            raise ConfigError(f"a tracking level of detail needs at least {MIN_LOD_TRIANGLES} triangles, "
                              f"got {triangles}")
        if triangles >= len(self.triangles):
            return self
        mesh = hashlib.sha256()
        for array in (self.vertices, self.triangles, self.skin_indices, self.skin_weights):
            mesh.update(np.ascontiguousarray(array).tobytes())
        key = cache_key(int(triangles), mesh.hexdigest(), version("open3d"), sources=(Path(__file__),))
        low = cached_arrays("lods", key, lambda: self._decimated(int(triangles)))
        return replace(self, name=f"{self.name}@{len(low['triangles'])}", vertices=np.array(low["vertices"]),
                       triangles=np.array(low["triangles"]), skin_indices=np.array(low["skin_indices"]),
                       skin_weights=np.array(low["skin_weights"]),
                       metadata={**self.metadata, "lod_triangles": int(len(low["triangles"]))})

    def _decimated(self, triangles: int) -> dict[str, np.ndarray]:
        """:meth:`tracking_lod`'s arrays, computed: vertices, triangles, skin_indices, skin_weights."""
        from scipy.spatial import cKDTree

        o3d = open3d()
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(self.vertices, dtype=np.float64)),
                                         o3d.utility.Vector3iVector(np.array(self.triangles, dtype=np.int32)))
        low = mesh.simplify_quadric_decimation(target_number_of_triangles=triangles)
        low.remove_unreferenced_vertices()
        low.remove_degenerate_triangles()
        verts = np.asarray(low.vertices, dtype=np.float64)
        _, nearest = cKDTree(self.vertices).query(verts)
        return {"vertices": verts, "triangles": np.asarray(low.triangles, dtype=np.int32),
                "skin_indices": self.skin_indices[nearest], "skin_weights": self.skin_weights[nearest]}


def body_frame_bind_matrices(heads: np.ndarray) -> np.ndarray:
    """(B, 4, 4) bind matrices with identity rotation and translation = the bone heads."""
    m = np.broadcast_to(np.eye(4), (len(heads), 4, 4)).copy()
    m[:, :3, 3] = heads
    return m
