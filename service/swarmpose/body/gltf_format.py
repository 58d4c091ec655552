"""Shared constants and helpers of swarmpose's glTF 2.0 / GLB reading and writing.

The body frame (X = the subject's left, Y up, Z forward, metres) *is* glTF's frame for
a character facing +Z, so no axis conversion happens either way. What glTF has no place
for (tracking-joint mapping, named points, metadata) travels in ``skin.extras`` under
:data:`EXTRAS_KEY`, tagged with :data:`FORMAT_NAME` and :data:`FORMAT_VERSION`.
"""

from __future__ import annotations

import numpy as np
import pygltflib as gl

EXTRAS_KEY = "swarmpose"
FORMAT_NAME = "swarmpose.skinned-body"
FORMAT_VERSION = 1
SYNTHETIC_ROOT = "swarmpose_root"
"""Name of the bone added above a skin that has several root joints."""

COMPONENT_DTYPES = {gl.BYTE: "<i1", gl.UNSIGNED_BYTE: "<u1", gl.SHORT: "<i2", gl.UNSIGNED_SHORT: "<u2",
                    gl.UNSIGNED_INT: "<u4", gl.FLOAT: "<f4"}
"""glTF accessor componentType -> little-endian numpy dtype string."""
TYPE_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
"""glTF accessor type -> number of components per element."""
NORMALIZERS = {gl.BYTE: 127.0, gl.UNSIGNED_BYTE: 255.0, gl.SHORT: 32767.0, gl.UNSIGNED_SHORT: 65535.0}
"""componentType -> divisor that maps a normalised integer accessor to [-1, 1] / [0, 1]."""


def affine_inverse(m: np.ndarray) -> np.ndarray:
    """Inverses (..., 4, 4) of affine matrices with an exact [0, 0, 0, 1] bottom row."""
    out = np.zeros_like(m, dtype=np.float64)
    inv = np.linalg.inv(m[..., :3, :3])
    out[..., :3, :3] = inv
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", inv, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out
