"""Which joint of a BVH skeleton plays which part of the body: the known families and a user's map.

A *joint map* names, for each key below, the BVH joint whose position is that point of the body
(the BVH joint ``LeftArm`` of a CMU file starts the upper arm, so it sits at the left shoulder):

* ``neck`` (the base of the neck, on the spine's chain), ``head`` (where the head meets the neck);
* per side (``left_`` / ``right_``): ``collar`` (the clavicle's inner end), ``shoulder``,
  ``elbow``, ``wrist``, ``hip``, ``knee``, ``ankle``; optionally ``toe`` (else the ankle's
  End Site gives the tip of the foot).

The pelvis is not named: it is the joint where the neck's and the left hip's chains meet, and the
spine is the chain from it to the neck. Known families are recognised by their names (the first
whose every required name the clip has); any other naming is given by a TOML file (read with
the standard library's ``tomllib``)::

    units = "cm"        # optional: m, dm, cm, mm, in or cmu (CMU's 1/0.45 inch)
    up = "y"            # optional: the file's up axis, x, y or z (a leading - for down)
    [joints]
    neck = "Neck"
    head = "Head"
    left_collar = "L_Clavicle"
    left_shoulder = "L_UpperArm"
    ...
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmpose.core.errors import MotionError
from swarmpose.core.toml_file import read_toml_file

SIDED = ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle")
REQUIRED = ("neck", "head", *(f"{side}_{part}" for side in ("left", "right") for part in SIDED))
OPTIONAL = ("left_toe", "right_toe")
KEYS = REQUIRED + OPTIONAL


def _sided(neck: str, head: str, left: dict[str, str], right_of) -> dict[str, str]:
    """A family's map from its left-side names; ``right_of`` turns a left name into the right one."""
    names = {"neck": neck, "head": head}
    for part, name in left.items():
        names[f"left_{part}"] = name
        names[f"right_{part}"] = right_of(name)
    return names


def _swap(a: str, b: str):
    return lambda name: name.replace(a, b, 1)


FAMILIES: dict[str, dict[str, str]] = {
    "CMU MotionBuilder / Mixamo": _sided("Neck", "Head", {
        "collar": "LeftShoulder", "shoulder": "LeftArm", "elbow": "LeftForeArm", "wrist": "LeftHand",
        "hip": "LeftUpLeg", "knee": "LeftLeg", "ankle": "LeftFoot", "toe": "LeftToeBase"}, _swap("Left", "Right")),
    "CMU 3dsMax": _sided("lowerneck", "Head", {
        "collar": "LeftCollar", "shoulder": "LeftShoulder", "elbow": "LeftElbow", "wrist": "LeftWrist",
        "hip": "LeftHip", "knee": "LeftKnee", "ankle": "LeftAnkle", "toe": "LeftToe"}, _swap("Left", "Right")),
    "old MakeHuman": _sided("Neck", "Head", {
        "collar": "Clavicle_L", "shoulder": "UpArm_L", "elbow": "LoArm_L", "wrist": "Hand_L",
        "hip": "UpLeg_L", "knee": "LoLeg_L", "ankle": "Foot_L", "toe": "Toe_L"}, _swap("_L", "_R")),
    "Daz (CMU cgspeed release)": _sided("neck", "head", {
        "collar": "lCollar", "shoulder": "lShldr", "elbow": "lForeArm", "wrist": "lHand",
        "hip": "lThigh", "knee": "lShin", "ankle": "lFoot"}, _swap("l", "r")),
    # CMU's ASF bones, reduced: the clavicles start where the neck does (the thorax's top).
    "CMU ASF": _sided("lclavicle", "head", {
        "collar": "lclavicle", "shoulder": "lhumerus", "elbow": "lradius", "wrist": "lhand",
        "hip": "lfemur", "knee": "ltibia", "ankle": "lfoot", "toe": "ltoes"}, _swap("l", "r")),
}
"""Family label -> key -> BVH joint name (exact, case-sensitive)."""

TORSO_UP_FAMILIES = ("CMU MotionBuilder / Mixamo", "CMU 3dsMax", "old MakeHuman")
"""Families whose motion keeps the reference pose's torso (pelvis -> neck) as the world's up, as
they were read before the file's own up axis was: the synthetic sequences every benchmark and
regression bound was measured on stay as they were (levelling them tilts a clip's root by its
reference pose's lean, 0.4-9 degrees, and turned the jumping jacks seen from behind into a mirrored
track). The other families and a user's map are levelled on the file's up axis."""

MAP_HELP = ("name your joints in a TOML file and pass it as FILE.bvh?map=names.toml: a [joints] table "
            f"with {', '.join(REQUIRED)} (optionally left_toe, right_toe) = your BVH joint names "
            "(docs/sources-and-detectors.md#your-own-mocap-naming)")


@dataclass(frozen=True)
class JointMap:
    """names: key (see :data:`KEYS`) -> BVH joint name; source: the family's label or the map
    file's path; units, up: what the map file states (None where it is silent)."""

    names: dict[str, str]
    source: str
    units: str | None = None
    up: str | None = None


@dataclass(frozen=True)
class Roles:
    """The clip's joint index (into ``clip.joint_names``) for every key of the map, plus ``pelvis``,
    ``spine_base`` and ``spine_top`` (the lowest and the highest spine joint below the neck);
    ``source`` says where the names came from."""

    index: dict[str, int]
    source: str


def read_joint_map(path: str | Path) -> JointMap:
    """A user's joint map from the TOML file at ``path`` (see the module docstring).

    Raises MotionError naming the file when it is missing, not TOML, lacks a ``[joints]`` table,
    names an unknown key or gives a name that is not a string.
    """
    path = Path(path).expanduser()
    data = read_toml_file(path, MotionError, "joint map", "check the path after ?map=", MAP_HELP)
    joints = data.get("joints")
    if not isinstance(joints, dict):
        raise MotionError(f"joint map {path}: has no [joints] table; {MAP_HELP}")
    unknown = sorted(set(joints) - set(KEYS))
    if unknown:
        raise MotionError(f"joint map {path}: unknown keys {unknown} in [joints]; the keys are {', '.join(KEYS)}")
    bad = sorted(k for k, v in joints.items() if not isinstance(v, str) or not v)
    if bad:
        raise MotionError(f"joint map {path}: {bad} must be BVH joint names in quotes")
    stray = sorted(set(data) - {"joints", "units", "up"})
    if stray:
        raise MotionError(f"joint map {path}: unknown settings {stray}; it holds units, up and [joints]")
    for key in ("units", "up"):
        if key in data and not isinstance(data[key], str):
            raise MotionError(f"joint map {path}: {key} must be a string, e.g. units = \"cm\", up = \"z\"")
    return JointMap(dict(joints), str(path), data.get("units"), data.get("up"))


def family_map(names: tuple[str, ...], clip_name: str) -> JointMap:
    """The known family whose every required joint name the clip has.

    Raises MotionError ("unknown BVH skeleton") naming the nearest family's joints the clip lacks
    and how to supply a map.
    """
    have = set(names)
    lacking = {label: [fam[k] for k in REQUIRED if fam[k] not in have] for label, fam in FAMILIES.items()}
    for label, missing in lacking.items():
        if not missing:
            return JointMap(FAMILIES[label], label)
    nearest = min(lacking, key=lambda label: len(lacking[label]))
    shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
    raise MotionError(
        f"BVH {clip_name}: unknown BVH skeleton: its joints ({shown}) are none of the known families "
        f"({', '.join(FAMILIES)}); the nearest, {nearest}, lacks "
        f"{', '.join(lacking[nearest])}; {MAP_HELP}")


def resolve_roles(joint_names: tuple[str, ...], parents: np.ndarray, joint_map: JointMap, clip_name: str) -> Roles:
    """Indices of the map's joints in a clip with ``joint_names`` and ``parents`` (J,), and the
    pelvis and spine found between them.

    Raises MotionError naming every required key the map lacks or whose joint the clip does not
    have, and when the neck is not above the pelvis on the spine's chain.
    """
    absent = [k for k in REQUIRED if k not in joint_map.names]
    if absent:
        raise MotionError(f"joint map {joint_map.source}: lacks {', '.join(absent)}; {MAP_HELP}")
    positions = {name: k for k, name in enumerate(joint_names)}
    unknown = [f"{key} = {name!r}" for key, name in joint_map.names.items() if name not in positions
               and key in REQUIRED]
    if unknown:
        raise MotionError(f"BVH {clip_name}: has no joint for {', '.join(unknown)} ({joint_map.source}); it has "
                          f"{', '.join(joint_names)}; correct the names in the map")
    index = {key: positions[name] for key, name in joint_map.names.items() if name in positions}

    def ancestors(j: int) -> list[int]:
        out = []
        while j >= 0:
            out.append(j)
            j = int(parents[j])
        return out

    chain = ancestors(index["neck"])
    below_hip = set(ancestors(index["left_hip"]))
    pelvis = next(j for j in chain if j in below_hip)  # the root at the latest: both chains end there
    spine = chain[:chain.index(pelvis)][::-1]  # pelvis-exclusive, bottom -> top, ends at the neck
    if len(spine) < 2:
        raise MotionError(f"BVH {clip_name}: no spine joint between the pelvis ({joint_names[pelvis]}) and the "
                          f"neck ({joint_names[index['neck']]}); map neck to a joint above the spine")
    index.update(pelvis=pelvis, spine_base=spine[0], spine_top=spine[-2])
    return Roles(index, joint_map.source)
