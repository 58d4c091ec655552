"""Mapping a foreign rig onto the tracking skeleton by its bone names.

Knows CMU/MotionBuilder, Mixamo, Unreal, Unity-humanoid and swarmpose bone names
(:data:`BONE_ROLES`). Works on plain arrays in the body frame (X = the subject's left,
Y up, Z forward; metres), so it does not depend on the file format the rig came from.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from swarmpose.body.landmarks import face_landmarks, foot_landmarks
from swarmpose.body.skeleton import JOINT_INDEX, POINT_NAMES
from swarmpose.core.errors import AssetError

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


def map_foreign_rig(names: list[str], parents: np.ndarray, heads: np.ndarray, path: Path):
    """bone_joint (B,), bone_fraction (B,), {point: bone} anchors and eye bones of a rig known by its bone names.

    ``names`` (B,) bone names, ``parents`` (B,) parent index (-1 = root, parents first),
    ``heads`` (B, 3) rest bone heads in metres, body frame; ``path`` only names the file in
    errors. The eye bones are ``(left, right)`` indices, each None when absent. Raises
    :class:`AssetError` when a required role is missing or the rig does not face +Z, Y up.
    """
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


def foreign_points(names, parents, heads, vertices, anchors, eyes):
    """Rest positions and carrier bones of every named point of a foreign rig.

    ``names`` (B,), ``parents`` (B,), ``heads`` (B, 3) m and ``anchors``/``eyes`` as from
    :func:`map_foreign_rig`; ``vertices`` (V, 3) m, body frame. Returns ``POINT_NAMES``
    (P,), carrier bones (P,) int64 and rest positions (P, 3) float64 m.
    """
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

