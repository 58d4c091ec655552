"""glTF 2.0 / GLB export of a :class:`SkinnedBody` (through pygltflib).

:func:`save_glb` writes one mesh (POSITION, NORMAL, JOINTS_0 uint16, WEIGHTS_0 float32,
uint32 indices), one skin whose joints are one node per bone (local TRS =
``inv(parent bind) @ bind``, inverse bind matrices = ``inv(bind)``), and keeps what glTF
has no place for (tracking-joint mapping, named points, metadata) in ``skin.extras``
under ``"swarmpose"`` (see :mod:`swarmpose.body.gltf_format`). Positions are metres in
the body frame, which is glTF's frame, so no axis conversion happens.

Accessors are float32, as glTF requires; the body's own positions, bind matrices and skin weights
also travel as float64 buffer views named by the extras' ``exact`` (no accessors: viewers ignore
them), so that :func:`~swarmpose.body.gltf_read.load_glb` gives back the same body to the last
bit, and a body and its export track identically. Two reasons: the quadric decimation that makes
the tracking mesh is not continuous in its input (the float32 rounding alone, at most 3e-8 m,
moved a MakeHuman tracking mesh's vertices by 0.8 mm on average and 41 mm at most), and the
tracker's search is chaotic (bind matrices 2e-8 m apart moved a 50-frame walk's Δ by 1.2 mm).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pygltflib as gl

from swarmpose.body.gltf_format import COMPONENT_DTYPES, EXTRAS_KEY, FORMAT_NAME, FORMAT_VERSION, affine_inverse
from swarmpose.body.kinematics import matrix_to_quaternion
from swarmpose.body.parametric_sdf import vertex_normals
from swarmpose.body.skeleton import JOINT_NAMES
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import OutputError


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
    binary GLB. The accessors' positions are float32 metres in the body frame (= glTF frame); the
    float64 positions, bind matrices and skin weights travel beside them (the module docstring).
    """
    path = Path(path)
    blob = bytearray()
    gltf = gl.GLTF2(asset=gl.Asset(generator="swarmpose", version="2.0"), scene=0)

    def add_view(data: bytes, align: int, target: int | None = None) -> int:
        """A buffer view of ``data`` starting ``align``-aligned in the buffer; its index."""
        blob.extend(b"\0" * (-len(blob) % align))
        gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data)
        return len(gltf.bufferViews) - 1

    def add(array: np.ndarray, component: int, kind: str, target: int | None = None, bounds: bool = False) -> int:
        data = np.ascontiguousarray(array, dtype=COMPONENT_DTYPES[component]).tobytes()
        acc = gl.Accessor(bufferView=add_view(data, 4, target), componentType=component, count=len(array), type=kind)
        if bounds:
            acc.min = [float(c) for c in array.min(axis=0)]
            acc.max = [float(c) for c in array.max(axis=0)]
        gltf.accessors.append(acc)
        return len(gltf.accessors) - 1

    def add_exact(array: np.ndarray) -> int:
        """A buffer view (no accessor) of ``array`` as little-endian float64; its index."""
        return add_view(np.ascontiguousarray(array, dtype="<f8").tobytes(), 8)

    vertices = np.asarray(body.vertices, dtype=np.float64)
    triangles = np.asarray(body.triangles, dtype=np.int64)
    exact = {"positions": add_exact(vertices), "bind_matrices": add_exact(body.bind_matrices),
             "skin_weights": add_exact(body.skin_weights)}
    extras = {**_extras(body), "exact": exact}
    attributes = gl.Attributes(
        POSITION=add(vertices.astype(np.float32), gl.FLOAT, gl.VEC3, gl.ARRAY_BUFFER, bounds=True),
        NORMAL=add(vertex_normals(vertices, triangles).astype(np.float32), gl.FLOAT, gl.VEC3, gl.ARRAY_BUFFER),
        JOINTS_0=add(np.asarray(body.skin_indices).astype(np.uint16), gl.UNSIGNED_SHORT, gl.VEC4, gl.ARRAY_BUFFER),
        WEIGHTS_0=add(np.asarray(body.skin_weights, dtype=np.float32), gl.FLOAT, gl.VEC4, gl.ARRAY_BUFFER),
    )
    indices = add(triangles.reshape(-1).astype(np.uint32), gl.UNSIGNED_INT, gl.SCALAR, gl.ELEMENT_ARRAY_BUFFER)
    binds = np.asarray(body.bind_matrices, dtype=np.float64)
    inverse = affine_inverse(binds).transpose(0, 2, 1).reshape(-1, 16)  # column-major
    ibm = add(inverse.astype(np.float32), gl.FLOAT, gl.MAT4)

    parents = np.asarray(body.bone_parents, dtype=np.int64)
    gltf.meshes.append(gl.Mesh(name=body.name, primitives=[gl.Primitive(attributes=attributes, indices=indices,
                                                                        mode=gl.TRIANGLES)]))
    gltf.nodes.append(gl.Node(name=body.name, mesh=0, skin=0))
    for b, name in enumerate(body.bone_names):
        local = binds[b] if parents[b] < 0 else affine_inverse(binds[parents[b]]) @ binds[b]
        gltf.nodes.append(_node_transform(name, local, [1 + int(c) for c in np.flatnonzero(parents == b)]))
    gltf.skins.append(gl.Skin(name=body.name, inverseBindMatrices=ibm, skeleton=1,
                              joints=list(range(1, 1 + len(body.bone_names))), extras={EXTRAS_KEY: extras}))
    gltf.scenes.append(gl.Scene(name=body.name, nodes=[0] + [1 + int(r) for r in np.flatnonzero(parents < 0)]))
    blob.extend(b"\0" * (-len(blob) % 4))  # the binary chunk's length: a multiple of 4
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

