"""Surface landmarks (nose, eyes, ears, heels, toes) found on a rest-pose mesh by geometry.

Body loaders know their joint centres from the rig; the face and foot points that 2D
detectors report lie on the skin, so they are picked from the mesh here. All inputs are
in the body frame (X left, Y up, Z forward), metres, rest pose facing +Z.
"""

from __future__ import annotations

import numpy as np

from swarmpose.core.errors import AssetError

EYE_OFFSET = np.array([0.032, 0.030, -0.025])
"""Eye position relative to the nose tip (|x|, y, z) used when a body has no eye joints."""


def _pick(vertices: np.ndarray, mask: np.ndarray, score: np.ndarray, what: str) -> np.ndarray:
    if not np.any(mask):
        raise AssetError(f"cannot place the {what} landmark: no mesh vertex in its search region")
    idx = np.flatnonzero(mask)
    return vertices[idx[np.argmax(score[idx])]].copy()


def face_landmarks(vertices: np.ndarray, head: np.ndarray, neck: np.ndarray,
                   eyes: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Nose tip, eyes and ears (each (3,)) from the mesh (V, 3) and the head/neck joints (3,).

    nose: the most forward vertex within 1 cm of the head's mid-sagittal plane, above the
    chin; eyes: given (left, right), else the nose tip + ``EYE_OFFSET`` mirrored; ears: the
    most lateral head vertex on each side within 2 cm of eye height, behind the face.
    """
    v = vertices
    head_region = (v[:, 1] > neck[1] + 0.04) & (np.hypot(v[:, 0] - head[0], v[:, 2] - head[2]) < 0.2)
    mid = head_region & (np.abs(v[:, 0] - head[0]) < 0.01) & (v[:, 1] > head[1] - 0.08)
    nose = _pick(v, mid, v[:, 2], "nose")
    if eyes is None:
        left_eye = nose + EYE_OFFSET
        right_eye = nose + EYE_OFFSET * np.array([-1.0, 1.0, 1.0])
    else:
        left_eye, right_eye = (np.asarray(e, dtype=np.float64) for e in eyes)
    eye_y = 0.5 * (left_eye[1] + right_eye[1])
    band = head_region & (np.abs(v[:, 1] - eye_y) < 0.02) & (v[:, 2] < nose[2] - 0.05)
    return {
        "nose": nose, "left_eye": left_eye, "right_eye": right_eye,
        "left_ear": _pick(v, band & (v[:, 0] > head[0]), v[:, 0], "left ear"),
        "right_ear": _pick(v, band & (v[:, 0] < head[0]), -v[:, 0], "right ear"),
    }


def foot_landmarks(vertices: np.ndarray, left_ankle: np.ndarray, right_ankle: np.ndarray) -> dict[str, np.ndarray]:
    """Toe tips (most forward foot vertex) and heels (most backward sole vertex) per side."""
    v = vertices
    out: dict[str, np.ndarray] = {}
    for side, ankle in (("left", left_ankle), ("right", right_ankle)):
        foot = (v[:, 1] < ankle[1] + 0.02) & (np.abs(v[:, 0] - ankle[0]) < 0.10)
        out[f"{side}_toe"] = _pick(v, foot, v[:, 2], f"{side} toe")
        sole = foot & (v[:, 1] < ankle[1] - 0.03)
        out[f"{side}_heel"] = _pick(v, sole, -v[:, 2], f"{side} heel")
    return out
