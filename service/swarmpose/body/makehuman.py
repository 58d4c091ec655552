"""Load the MakeHuman base body with the CMU MotionBuilder rig, personalised by macro targets.

The assets directory (``shared/assets/bodies/makehuman``) holds ``base.obj`` (decimetres,
Y up, facing +Z, A-pose), ``rigs/mpfb_rig.cmu_mb.json`` + ``rigs/mpfb_weights.cmu_mb.json``
and ``targets/macrodetails/**.target`` (``vertex dx dy dz`` lines, decimetres). Targets move
every vertex of the file, the ``joint-*`` cubes included, so the rig follows the shape:
joint positions are the centroids of the cubes *after* the targets are applied.

Mapping onto the tracking skeleton (axes as in :mod:`swarmpose.body.skeleton`): Hips is
the root; LowerBack, Spine and Spine1 take a third of the spine joint each; Neck and Neck1
half of the neck joint each; LeftShoulder/RightShoulder are the collars, Left/RightArm the
shoulders, Left/RightForeArm the elbows, Left/RightUpLeg the hips, Left/RightLeg the knees,
Left/RightFoot the ankles; LHipJoint/RHipJoint, Head, hands, fingers and toes are rigid.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from swarmpose.body.landmarks import face_landmarks, foot_landmarks
from swarmpose.body.skeleton import JOINT_INDEX
from swarmpose.body.skinned import SkinnedBody, body_frame_bind_matrices, sparse_skin
from swarmpose.core.cache import cache_key, cached_arrays
from swarmpose.core.errors import AssetError, ConfigError

DECIMETRE = 0.1
RIG_FILE = "rigs/mpfb_rig.cmu_mb.json"
WEIGHTS_FILE = "rigs/mpfb_weights.cmu_mb.json"
TARGET_DIR = "targets/macrodetails"

_SIDES = (("left", "Left", "L"), ("right", "Right", "R"))


SHORT_WEIGHT = {"male": 0.5, "female": 0.15}
"""The README's 'short' recipe (min-height target at ~0.5) makes the female body 1.42 m;
0.15 keeps her at 1.55 m, the low end of the heights the tracker is evaluated on."""


def _preset_table() -> dict[str, dict[str, float]]:
    """The recipes of the assets README, for both sexes."""
    table: dict[str, dict[str, float]] = {}
    for g in ("male", "female"):
        base = {f"caucasian-{g}-young": 1.0}
        table[g] = base
        table[f"{g}-heavy"] = {**base, f"universal-{g}-young-averagemuscle-maxweight": 1.0}
        table[f"{g}-slim"] = {**base, f"universal-{g}-young-averagemuscle-minweight": 1.0}
        table[f"{g}-muscular"] = {**base, f"universal-{g}-young-maxmuscle-averageweight": 1.0}
        table[f"{g}-tall"] = {**base, f"height/{g}-young-averagemuscle-averageweight-maxheight": 0.25}
        table[f"{g}-short"] = {**base, f"height/{g}-young-averagemuscle-averageweight-minheight": SHORT_WEIGHT[g]}
    table["neutral"] = {}
    return table


PRESETS: dict[str, dict[str, float]] = _preset_table()
"""Shape preset name -> {target path below targets/macrodetails (no suffix): weight}."""

TRACKING_BONES: dict[str, tuple[str, float]] = {
    "LowerBack": ("spine", 1 / 3), "Spine": ("spine", 1 / 3), "Spine1": ("spine", 1 / 3),
    "Neck": ("neck", 0.5), "Neck1": ("neck", 0.5),
    **{f"{s}Shoulder": (f"{side}_collar", 1.0) for side, s, _ in _SIDES},
    **{f"{s}Arm": (f"{side}_shoulder", 1.0) for side, s, _ in _SIDES},
    **{f"{s}ForeArm": (f"{side}_elbow", 1.0) for side, s, _ in _SIDES},
    **{f"{s}UpLeg": (f"{side}_hip", 1.0) for side, s, _ in _SIDES},
    **{f"{s}Leg": (f"{side}_knee", 1.0) for side, s, _ in _SIDES},
    **{f"{s}Foot": (f"{side}_ankle", 1.0) for side, s, _ in _SIDES},
}
"""CMU MotionBuilder bone -> (tracking joint, share of its angles)."""


def _joint_points(side: str, s: str) -> dict[str, tuple[str, str]]:
    """Named point -> (bone carrying it, bone whose head it is) for one side."""
    return {
        f"{side}_clavicle": (f"{s}Shoulder", f"{s}Shoulder"),
        f"{side}_shoulder": (f"{s}Arm", f"{s}Arm"),
        f"{side}_elbow": (f"{s}ForeArm", f"{s}ForeArm"),
        f"{side}_wrist": (f"{s}Hand", f"{s}Hand"),
        f"{side}_hip": (f"{s}UpLeg", f"{s}UpLeg"),
        f"{side}_knee": (f"{s}Leg", f"{s}Leg"),
        f"{side}_ankle": (f"{s}Foot", f"{s}Foot"),
    }


# ----------------------------------------------------------------------------- file parsing
GROUP_PREFIX = "group:"
"""The cache entry of base.obj stores each group's faces under this prefix and its name."""


@lru_cache(maxsize=4)
def _read_obj(path: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """All vertices (N, 3) in decimetres and each group's faces as vertex index arrays; from the
    cache when this file was read before (parsing its text takes a start 0.3-0.7 s)."""
    key = cache_key("makehuman-obj", sources=(Path(path), Path(__file__)))
    arrays = cached_arrays("makehuman_obj", key, lambda: _parse_obj(path))
    groups = {name[len(GROUP_PREFIX):]: faces for name, faces in arrays.items() if name.startswith(GROUP_PREFIX)}
    return arrays["vertices"], groups


def _parse_obj(path: str) -> dict[str, np.ndarray]:
    """base.obj's ``vertices`` and its groups' faces (``group:NAME``), parsed from the text."""
    verts: list[list[float]] = []
    faces: dict[str, list[list[int]]] = {}
    group = "default"
    try:
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("v "):
                    verts.append([float(x) for x in line.split()[1:4]])
                elif line.startswith("g "):
                    group = line.split(maxsplit=1)[1].strip()
                elif line.startswith("f "):
                    faces.setdefault(group, []).append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    except (OSError, ValueError, IndexError) as exc:
        raise AssetError(f"cannot read MakeHuman mesh {path}: {exc}") from exc
    if "body" not in faces:
        raise AssetError(f"{path} has no 'g body' group; is it the MakeHuman base.obj?")
    arrays = {}
    for g, f in faces.items():
        lengths = {len(x) for x in f}
        if lengths == {4}:
            arrays[g] = np.asarray(f, dtype=np.int64)
        else:
            arrays[g] = np.asarray([x[:3] for x in f] + [[x[0], x[2], x[3]] for x in f if len(x) == 4], dtype=np.int64)
    return {"vertices": np.asarray(verts, dtype=np.float64), **{GROUP_PREFIX + g: f for g, f in arrays.items()}}


@lru_cache(maxsize=64)
def _read_target(path: Path, n_vertices: int) -> np.ndarray:
    """A dense (N, 3) displacement in decimetres from a .target file (cached, read-only)."""
    try:
        data = np.loadtxt(path, comments="#", ndmin=2)
    except (OSError, ValueError) as exc:
        raise AssetError(f"cannot read MakeHuman target {path}: {exc}") from exc
    out = np.zeros((n_vertices, 3))
    if data.size:
        if data.shape[1] != 4:
            raise AssetError(f"{path}: expected lines 'vertex dx dy dz', found {data.shape[1]} columns")
        out[data[:, 0].astype(np.int64)] = data[:, 1:4]
    out.setflags(write=False)
    return out


def _triangulate(quads: np.ndarray) -> np.ndarray:
    if quads.shape[1] == 3:
        return quads
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def _topological(rig: dict) -> list[str]:
    order: list[str] = []
    done: set[str] = set()

    def visit(name: str, stack: tuple[str, ...] = ()) -> None:
        if name in done:
            return
        if name in stack:
            raise AssetError(f"rig has a cycle through bone {name}")
        parent = rig[name].get("parent") or ""
        if parent:
            if parent not in rig:
                raise AssetError(f"rig bone {name} has unknown parent {parent}")
            visit(parent, stack + (name,))
        done.add(name)
        order.append(name)

    roots = [n for n, b in rig.items() if not b.get("parent")]
    if len(roots) != 1:
        raise AssetError(f"rig must have exactly one root bone, found {roots}")
    for name in sorted(rig, key=lambda n: n != roots[0]):
        visit(name)
    return order


# ----------------------------------------------------------------------------- loader
def _locate(spec: dict, centroids, verts: np.ndarray, bone: str) -> np.ndarray:
    strategy = spec.get("strategy")
    if strategy == "CUBE":
        return centroids(spec["cube_name"])
    if strategy == "MEAN":
        return verts[np.asarray(spec["vertex_indices"], dtype=np.int64)].mean(axis=0)
    raise AssetError(f"rig bone {bone}: unsupported placement strategy {strategy!r}")


def resolve_targets(preset: str) -> dict[str, float]:
    """The target recipe of ``preset``; a ConfigError lists the valid names."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown MakeHuman shape preset {preset!r}; choose one of {', '.join(sorted(PRESETS))}")
    return PRESETS[preset]


@dataclass(frozen=True, eq=False)
class _RigAssets:
    """What every shape of the MakeHuman body shares: the rig's bone order and parents, the
    body group's triangles and the sparse skin (the weights do not depend on the shape)."""

    names: list[str]
    rig: dict
    parents: np.ndarray
    body_faces: np.ndarray
    used: np.ndarray
    skin_idx: np.ndarray
    skin_w: np.ndarray


@lru_cache(maxsize=4)
def _rig_assets(directory: str) -> _RigAssets:
    root = Path(directory)
    all_verts, groups = _read_obj(str(root / "base.obj"))
    try:
        rig = json.loads((root / RIG_FILE).read_text())
    except (OSError, ValueError) as exc:
        raise AssetError(f"cannot read the cmu_mb rig {root / RIG_FILE}: {exc}") from exc
    names = _topological(rig)
    index = {n: i for i, n in enumerate(names)}
    parents = np.array([index[rig[n]["parent"]] if rig[n].get("parent") else -1 for n in names])
    key = cache_key("makehuman-skin", names, sources=(root / "base.obj", root / WEIGHTS_FILE, Path(__file__)))
    skin = cached_arrays("makehuman_skin", key, lambda: _skin(all_verts, groups, names, root))
    return _RigAssets(names, rig, parents, skin["body_faces"], skin["used"], skin["skin_idx"], skin["skin_w"])


def _skin(all_verts: np.ndarray, groups: dict[str, np.ndarray], names: list[str], root: Path) -> dict[str, np.ndarray]:
    """The body group's triangles (T, 3) over its own vertices, which of base.obj's vertices
    those are (``used``), and their sparse skin over the bones ``names`` (read from the weights
    file, 3 MB of JSON)."""
    try:
        weights = json.loads((root / WEIGHTS_FILE).read_text())["weights"]
    except (OSError, ValueError, KeyError) as exc:
        raise AssetError(f"cannot read the cmu_mb weights {root / WEIGHTS_FILE}: {exc}") from exc
    index = {n: i for i, n in enumerate(names)}
    body_faces = _triangulate(groups["body"])
    used = np.unique(body_faces)
    remap = np.full(len(all_verts), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    dense = np.zeros((len(all_verts), len(names)))
    for bone, pairs in weights.items():
        if bone not in index:
            raise AssetError(f"weights name bone {bone!r}, which the rig lacks")
        arr = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
        dense[arr[:, 0].astype(np.int64), index[bone]] = arr[:, 1]
    skin_idx, skin_w = sparse_skin(dense[used], len(used))
    return {"body_faces": remap[body_faces].astype(np.int32), "used": used, "skin_idx": skin_idx, "skin_w": skin_w}


def _check_directory(root: Path) -> None:
    if not (root / "base.obj").is_file():
        raise AssetError(f"no base.obj in {root}; pass the MakeHuman assets directory "
                         "(shared/assets/bodies/makehuman)")


def shaped_vertices(directory: str | Path, recipe: dict[str, float]) -> np.ndarray:
    """Every vertex of base.obj (N, 3), decimetres, with the targets of ``recipe`` ({target path
    below targets/macrodetails, no suffix: weight}) added."""
    root = Path(directory)
    _check_directory(root)
    verts = _read_obj(str(root / "base.obj"))[0].copy()
    for target, weight in recipe.items():
        if weight == 0:
            continue
        path = root / TARGET_DIR / f"{target}.target"
        if not path.is_file():
            raise AssetError(f"target {path} is missing from the MakeHuman assets")
        verts += weight * _read_target(path, len(verts))
    return verts


@lru_cache(maxsize=16)
def load_makehuman(directory: str | Path, preset: str = "neutral") -> SkinnedBody:
    """The MakeHuman body in ``directory`` shaped by ``preset`` (see :data:`PRESETS`).

    Returns a :class:`SkinnedBody` in metres in the body frame, root (Hips head) at the
    origin, 13,380 vertices, 26,756 triangles, 31 bones, ≤ 4 influences per vertex.
    """
    recipe = resolve_targets(preset)
    return makehuman_body(directory, recipe, f"makehuman:{preset}", {"preset": preset})


def makehuman_body(directory: str | Path, recipe: dict[str, float], name: str,
                   metadata: dict | None = None) -> SkinnedBody:
    """The MakeHuman body in ``directory`` with the targets of ``recipe`` ({target: weight}) applied,
    named ``name``; ``metadata`` is added to the body's own (source, directory, targets)."""
    root = Path(directory)
    verts = shaped_vertices(root, recipe)
    groups = _read_obj(str(root / "base.obj"))[1]
    assets = _rig_assets(str(root))
    names, rig = assets.names, assets.rig
    index = {n: i for i, n in enumerate(names)}

    def centroid(cube: str) -> np.ndarray:
        if cube not in groups:
            raise AssetError(f"base.obj has no joint cube group {cube!r}")
        return verts[np.unique(groups[cube])].mean(axis=0)

    heads = np.stack([_locate(rig[n]["head"], centroid, verts, n) for n in names])
    tails = np.stack([_locate(rig[n]["tail"], centroid, verts, n) for n in names])
    origin = heads[index["Hips"]].copy()

    def to_body(p: np.ndarray) -> np.ndarray:
        return (p - origin) * DECIMETRE

    body_verts = to_body(verts[assets.used])
    heads_m = to_body(heads)

    points: dict[str, tuple[str, np.ndarray]] = {}
    for side, s, _ in _SIDES:
        for point, (carrier, owner) in _joint_points(side, s).items():
            points[point] = (carrier, heads_m[index[owner]])
    points["neck"] = ("Neck", heads_m[index["Neck"]])
    points["spine"] = ("LowerBack", heads_m[index["LowerBack"]])
    points["head"] = ("Head", 0.5 * (heads_m[index["Head"]] + to_body(tails[index["Head"]])))
    points["mid_hip"] = ("Hips", 0.5 * (heads_m[index["LeftUpLeg"]] + heads_m[index["RightUpLeg"]]))
    eyes = (to_body(centroid("joint-l-eye")), to_body(centroid("joint-r-eye")))
    for point_name, pos in face_landmarks(body_verts, points["head"][1], points["neck"][1], eyes).items():
        points[point_name] = ("Head", pos)
    for point_name, pos in foot_landmarks(body_verts, points["left_ankle"][1], points["right_ankle"][1]).items():
        points[point_name] = (("LeftFoot" if point_name.startswith("left") else "RightFoot"), pos)

    bone_joint = np.array([JOINT_INDEX[TRACKING_BONES[n][0]] if n in TRACKING_BONES else -1 for n in names])
    bone_fraction = np.array([TRACKING_BONES[n][1] if n in TRACKING_BONES else 0.0 for n in names])
    point_names = tuple(points)
    return SkinnedBody(
        name=name,
        vertices=body_verts,
        triangles=assets.body_faces,
        skin_indices=assets.skin_idx,
        skin_weights=assets.skin_w,
        bone_names=tuple(names),
        bone_parents=assets.parents,
        bone_heads=heads_m,
        bind_matrices=body_frame_bind_matrices(heads_m),
        bone_joint=bone_joint,
        bone_fraction=bone_fraction,
        point_names=point_names,
        point_bones=np.array([index[points[p][0]] for p in point_names]),
        point_rest=np.stack([points[p][1] for p in point_names]),
        metadata={"source": "makehuman", "directory": str(root), "targets": dict(recipe), **(metadata or {})},
    )
