"""Clothes for the synthetic renders (``swarmpose synth --clothes``): a colour per body part.

A body rendered in one colour shows an arm held over its torso by shading alone, where real
people's sleeves, skin and trousers draw the limb's outline. Clothes did not help MoveNet, so the
plain render stays the default and every benchmark's; the option is for other RGB networks. Each triangle
of a body takes the colour of the garment over the part that moves it (the bone with the largest
skinning weight at most of its vertices, up the bone tree to the first bone a tracking joint drives):

* skin: the neck's bones (neck, head) and the elbows' (forearms, hands): a short-sleeved shirt;
* shirt (the person's palette colour, :data:`~swarmpose.sim.render.PERSON_ALBEDOS`): the spine,
  collars and shoulders (upper arms);
* trousers: the pelvis and the legs down to the ankles;
* shoes: the ankles' bones (feet, toes).

The depth is unchanged: only the colour image and what a 2D network makes of it.
"""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import JOINT_NAMES
from swarmpose.body.skinned import SkinnedBody
from swarmpose.sim.render import PERSON_ALBEDOS, person_albedo

SKIN_ALBEDOS = (np.array([0.87, 0.68, 0.55]), np.array([0.55, 0.38, 0.27]), np.array([0.95, 0.80, 0.70]),
                np.array([0.70, 0.50, 0.36]))
"""Skin tones (RGB 0..1) of people 1, 2, ... (repeating)."""
TROUSER_ALBEDOS = (np.array([0.18, 0.22, 0.36]), np.array([0.30, 0.27, 0.24]), np.array([0.14, 0.14, 0.16]))
"""Trousers (RGB 0..1) of people 1, 2, ... (repeating)."""
SHOE_ALBEDO = np.array([0.10, 0.09, 0.09])
FIRST_SHIRT = np.array([0.20, 0.55, 0.60])
"""Person 1's shirt (teal): the palette's first colour is the plain render's skin-like body."""
GARMENT_OF_JOINT = {"neck": "skin", "left_elbow": "skin", "right_elbow": "skin", "spine": "shirt",
                    "left_collar": "shirt", "right_collar": "shirt", "left_shoulder": "shirt",
                    "right_shoulder": "shirt", "left_hip": "trousers", "right_hip": "trousers",
                    "left_knee": "trousers", "right_knee": "trousers", "left_ankle": "shoes", "right_ankle": "shoes"}
"""The garment over the bones each tracking joint moves; the root's bones (pelvis) wear trousers."""


def shirt_albedo(index: int) -> np.ndarray:
    """The shirt (3,) RGB 0..1 of the person at 0-based ``index`` of a scene: the plain render's
    palette colour (:func:`~swarmpose.sim.render.person_albedo`), but teal where that is the
    palette's first, a skin tone."""
    return FIRST_SHIRT if index % len(PERSON_ALBEDOS) == 0 else person_albedo(index)


def bone_garments(body: SkinnedBody) -> list[str]:
    """The garment (:data:`GARMENT_OF_JOINT`) over each of ``body``'s bones: that of the first bone
    up the tree (itself included) that a tracking joint drives; trousers for the root's."""
    out: list[str] = []
    for b in range(len(body.bone_names)):
        k = b
        while k >= 0 and body.bone_joint[k] < 0:
            k = int(body.bone_parents[k])
        out.append("trousers" if k < 0 else GARMENT_OF_JOINT[JOINT_NAMES[int(body.bone_joint[k])]])
    return out


def clothing_albedo(body: SkinnedBody, shirt: np.ndarray, index: int) -> np.ndarray:
    """(F, 3) RGB 0..1 per triangle of ``body``: the garment (:func:`bone_garments`) of the bone
    with the largest skinning weight at two or three of the triangle's vertices (at the first
    where all three differ), so that hems follow the triangles rather than zigzag; ``shirt`` (3,)
    the shirt's colour; ``index`` (0-based, the person's place in the scene) picks the skin tone
    and the trousers."""
    colours = {"skin": SKIN_ALBEDOS[index % len(SKIN_ALBEDOS)], "shirt": np.asarray(shirt, float),
               "trousers": TROUSER_ALBEDOS[index % len(TROUSER_ALBEDOS)], "shoes": SHOE_ALBEDO}
    palette = np.array([colours[g] for g in bone_garments(body)])  # (B, 3)
    weights = np.asarray(body.skin_weights)
    main_bone = np.take_along_axis(np.asarray(body.skin_indices), np.argmax(weights, axis=1)[:, None], axis=1)[:, 0]
    corners = main_bone[np.asarray(body.triangles)]  # (F, 3) each vertex's main bone
    pair = corners[:, 1] == corners[:, 2]  # the second and third agree: theirs is the majority
    return palette[np.where(pair, corners[:, 1], corners[:, 0])]
