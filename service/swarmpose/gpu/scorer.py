"""``ParticleScorer``: the depth term of every PSO particle in one OpenCL launch.

Per frame, :meth:`ParticleScorer.set_observation` resamples the observed depth inside the
person's box B to a TW x TH tile (see :mod:`swarmpose.gpu.tile`) and uploads it. Per
generation, :meth:`ParticleScorer.evaluate` uploads the P poses (P x 36 float32), launches
``cl/score.cl`` once (one work-group per particle: forward kinematics, the named points, the
joint and penetration terms against the targets of :meth:`ParticleScorer.set_joint_targets`,
skin, project, rasterise a local z-buffer, reduce) and reads back one packed result per
particle: the depth term's sum and counts and the three terms (the named points, P x NPT x
3, only when asked); with ``render=False`` no depth term (a joint-term-only objective).
:meth:`ParticleScorer.score_transforms` scores bone transforms computed elsewhere (the
numpy FK, :meth:`ParticleScorer.transforms`, the oracle of the device's).

The per-pixel term is ``min(|d_h - d_o|, T)`` over tile pixels with ``d_o > 0``; where the
model does not cover a pixel ``d_h = 0`` (the renderer's "no depth"), so the term is
``min(d_o, T)``, which is ``T`` for every real sensor depth (>= 0.4 m > T = 0.3 m): a
missed observed pixel costs the full penalty, as the paper implies. Counts (see
:data:`COUNT_NAMES`) let the objective normalise (E_D = sum / N_P) and compute N_P.

Bad input: zero particles give empty results without a launch; non-finite poses or a
zero quaternion raise :class:`ShapeError` naming the rows; an all-invalid observation
gives sums 0 and observed counts 0; a box partly outside the image is clipped to it, one
wholly outside gives an all-invalid observation. Triangles with a vertex nearer than
``znear`` are skipped (not clipped). Output buffers are poisoned (NaN / -1) before every
launch, so a result the kernel did not write cannot pass for a score.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from swarmpose.body.kinematics import as_poses, skinning_transforms
from swarmpose.body.skeleton import POSE_DIM
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError, ShapeError
from swarmpose.gpu.context import ClContext, describe
from swarmpose.gpu.fk_tables import FkTables, fk_tables
from swarmpose.gpu.reference import COUNT_NAMES
from swarmpose.gpu.tile import TileBox, clip_box

__all__ = ["ParticleScorer", "Evaluation", "COUNT_NAMES"]

TERM_NAMES = ("E_J2D", "E_J3D", "E_P")
"""The objective's terms the kernel computes from the named points (see cl/include/joint_term.h)."""


@lru_cache(maxsize=8)
def device_mesh(body: SkinnedBody) -> tuple[FkTables, dict[str, np.ndarray]]:
    """``body``'s FK tables and the device layout of its mesh, skin and tables (contiguous
    float32 / int32 arrays by buffer name), made once per body: a shape fit uploads each
    candidate body to one scorer per key frame. (Bodies hash by identity.)"""
    tables = fk_tables(body)
    rest = np.zeros((len(body.vertices), 4), np.float32)
    rest[:, :3] = body.vertices
    tris = np.zeros((len(body.triangles), 4), np.int32)
    tris[:, :3] = body.triangles
    arrays = {"rest": rest, "idx": np.ascontiguousarray(body.skin_indices, np.int32),
              "w": np.ascontiguousarray(body.skin_weights, np.float32), "tris": tris,
              "steps": tables.steps, "links": tables.links, "bone_data": tables.bone_data,
              "point_bone": tables.point_bone, "point_rest": tables.point_rest}
    return tables, {k: np.ascontiguousarray(v) for k, v in arrays.items()}


@dataclass(frozen=True)
class Evaluation:
    """One launch's results for P poses: sums (P,) m and counts {name: (P,) int64} of the depth
    term (0 without rendering), the named points (P, NPT, 3) m, camera frame (None when not
    read back), and the terms {name: (P,)} of :data:`TERM_NAMES` (E_J2D px, E_J3D mm, E_P cm;
    see :meth:`ParticleScorer.set_joint_targets`)."""

    sums: np.ndarray
    counts: dict[str, np.ndarray]
    points: np.ndarray | None
    terms: dict[str, np.ndarray]


class ParticleScorer:
    """Scores pose hypotheses of one body against one depth tile per frame.

    body: the (tracking level of detail of the) skinned body, used as given; intrinsics:
    the camera's; tile: (TW, TH) tile pixels; threshold: T in m; context: the
    :class:`~swarmpose.gpu.context.ClContext` to run on, or a device spec (see
    :mod:`swarmpose.gpu.context`; None or "": the default device);
    cull_backfaces: skip back faces (exact for closed meshes); local_size: work-items per
    particle (None: 1 on CPUs, 64 on other devices); atomic: use atomic_max on the local
    z-buffer (None: only when local_size > 1); znear: near plane in m; vector_raster: on the
    one-work-item (CPU) layout with a tile width that is a multiple of 8, scan, set up and draw
    the triangles 8 at a time in vector lanes (False: one at a time, the reference the tests
    compare it with; the z-buffers are bit-identical).

    ``last_timings`` holds the split of the last call in seconds: upload_s,
    kernel_s and readback_s (OpenCL event times) and wall_s (enqueue to results). One
    scorer serves one thread at a time.
    """

    def __init__(self, body: SkinnedBody, intrinsics: Intrinsics, tile: tuple[int, int] = (64, 64),
                 threshold: float = 0.30, context: ClContext | str | None = None, cull_backfaces: bool = True,
                 local_size: int | None = None, atomic: bool | None = None, znear: float = 0.05,
                 vector_raster: bool = True):
        import pyopencl as cl

        self._cl = cl
        self.body = body
        self.intrinsics = intrinsics
        self.tw, self.th = (int(x) for x in tile)
        if self.tw < 1 or self.th < 1:
            raise ConfigError(f"tile size {tile} must be at least 1x1 pixels")
        if not (np.isfinite(threshold) and threshold > 0):
            raise ConfigError(f"threshold T = {threshold} m must be positive")
        self.threshold = float(threshold)
        if len(body.triangles) == 0:
            raise ShapeError(f"{body.name}: the body has no triangles to render")
        self.cl_context = context if isinstance(context, ClContext) else ClContext.for_spec(context)
        self.device, self.context, self.queue = self.cl_context.device, self.cl_context.context, self.cl_context.queue
        wg = int(local_size or (1 if self.cl_context.is_cpu else 64))
        if wg < 1 or wg & (wg - 1) or wg > self.device.max_work_group_size:
            raise ConfigError(f"local_size {wg} must be a power of two <= {self.device.max_work_group_size}")
        self.local_size = wg
        self.atomic = bool(wg > 1 if atomic is None else atomic)
        if wg > 1 and not self.atomic:
            raise ConfigError("local_size > 1 needs atomic=True (work-items share the z-buffer)")
        nv, nf, nb = len(body.vertices), len(body.triangles), len(body.bone_names)
        tables = device_mesh(body)[0]
        sizes = tables.defines  # FK scratch: NJ joint and NB frame quaternions, NPT points (float4 each)
        vector = bool(vector_raster) and wg == 1 and not self.atomic and self.tw % 8 == 0
        need = (nb * 48 + (nb + sizes["NJ"] + sizes["NPT"]) * 16 + nv * (16 if vector else 24)
                + self.tw * self.th * 4 + (wg * 20 if wg > 1 else (nf + 8) * 4))
        if need > self.device.local_mem_size:
            raise ConfigError(f"{body.name} ({nv} vertices) with a {self.tw}x{self.th} tile needs {need} bytes of "
                              f"local memory, {describe(self.device)} has {self.device.local_mem_size}; "
                              "use a smaller tracking LOD (body.tracking_lod) or tile")
        self.point_count = len(tables.point_bone)
        self.defines = {"NV": nv, "NF": nf, "NB": nb, "TW": self.tw, "TH": self.th, "WG": wg,
                        "ZATOMIC": self.atomic, "CULL": bool(cull_backfaces), "ZNEAR": float(znear),
                        "VECROW": vector, **sizes}
        self._mesh = self._upload_mesh(body)
        self._capacity = 0
        self._tile_box: TileBox | None = None
        self._observed: np.ndarray | None = None
        self._obs_buf = None
        self._tiles_buf = self._bones_out_buf = None
        self._joint_args = (np.int32(0), np.int32(0), np.int32(0), np.zeros(4, np.float32), np.zeros(4, np.float32))
        self.joint_targets_owner: object = None
        self._state_version = 0  # bumped whenever a kernel argument changes
        self._args_state: dict[tuple[bool, bool], tuple[int, bool]] = {}
        self._kernels: dict[tuple[bool, bool], object] = {}
        self._last_launch: tuple | None = None  # (upload event, kernel event, read events, wall s)

    # ------------------------------------------------------------------ setup
    def set_body(self, body: SkinnedBody) -> None:
        """Score ``body`` from now on: another shape of the same topology (vertex, triangle,
        bone and named-point counts, as :class:`~swarmpose.body.shape_space.ShapeSpace` keeps
        them). Only the buffers whose contents differ are copied (a shape of one space moves the
        rest vertices, bone heads and named points; the skin, triangles and FK steps stay): no
        program is built again."""
        tables, arrays = device_mesh(body)
        have = (self.defines["NV"], self.defines["NF"], self.defines["NB"], self.point_count)
        got = (len(body.vertices), len(body.triangles), len(body.bone_names), len(tables.point_bone))
        if have != got or tables.defines["NJ"] != self.defines["NJ"]:
            raise ShapeError(f"{body.name}: (vertices, triangles, bones, points) {got} differ from the scorer's "
                             f"{have}; build a new scorer for another topology")
        held = self._mesh_host
        for name, array in arrays.items():
            if array is not held[name] and not np.array_equal(array, held[name]):
                self._cl.enqueue_copy(self.queue, self._mesh[name], array, is_blocking=True)
        self._mesh_host = dict(arrays)
        self.body = body

    def _upload_mesh(self, body: SkinnedBody) -> dict:
        cl = self._cl
        mf = cl.mem_flags
        self._mesh_host = dict(device_mesh(body)[1])
        arrays = {**self._mesh_host, "no_observation": np.zeros(1, np.float32)}
        buffers = {k: cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for k, a in arrays.items()}
        npt = len(self._mesh_host["point_bone"])
        for name, size in (("tgt2d", npt * 16), ("tgt3d", npt * 16), ("pairs", max(npt // 2, 1) * 8), ("pen", 32)):
            buffers[name] = cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.zeros(size, np.uint8))
        return buffers

    def _kernel(self, write_tiles: bool, fk: bool):
        key = (write_tiles, fk)
        if key not in self._kernels:
            prg = self.cl_context.program("score.cl", {**self.defines, "WRITE_TILES": write_tiles, "FK": fk})
            self._kernels[key] = self._cl.Kernel(prg, "score_particles")  # one per scorer
        return self._kernels[key]

    def _ensure_capacity(self, p: int, tiles: bool) -> None:
        cl = self._cl
        if p > self._capacity:
            cap = max(p, 2 * self._capacity, 16)
            nb = self.defines["NB"]
            self._input_buf = cl.Buffer(self.context, cl.mem_flags.READ_ONLY, cap * max(nb * 48, POSE_DIM * 4))
            self._points_buf = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, cap * self.point_count * 16)
            self._results_buf = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, cap * 32)
            self._results_host = np.empty((cap, 8), np.float32)
            self._tiles_buf = self._bones_out_buf = None
            self._capacity = cap
            self._state_version += 1
        if tiles and self._tiles_buf is None:
            cap = self._capacity
            self._tiles_buf = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, cap * self.tw * self.th * 4)
            self._bones_out_buf = cl.Buffer(self.context, cl.mem_flags.WRITE_ONLY, cap * self.defines["NB"] * 48)
            self._state_version += 1

    # ------------------------------------------------------------------ per frame
    def set_observation(self, depth: np.ndarray, box) -> None:
        """Upload the observation of a frame: depth (H, W) m (0 / NaN = none) at the
        intrinsics' size, box (u0, v0, bw, bh) pixels, clipped to the image."""
        depth = np.asarray(depth)
        shape = (self.intrinsics.height, self.intrinsics.width)
        if depth.shape != shape:
            raise ShapeError(f"depth has shape {depth.shape}, expected {shape} (the intrinsics' height, width)")
        clipped = clip_box(box, self.intrinsics.width, self.intrinsics.height)
        if clipped is None:  # wholly outside: keep the box, observe nothing
            tb = TileBox(*(float(x) for x in box), self.tw, self.th)
            observed = np.zeros((self.th, self.tw), np.float32)
        else:
            tb = TileBox(*clipped, self.tw, self.th)
            observed = tb.resample(depth)
        self._tile_box, self._observed = tb, observed
        cl = self._cl
        if self._obs_buf is None:
            self._obs_buf = cl.Buffer(self.context, cl.mem_flags.READ_ONLY, observed.nbytes)
        cl.enqueue_copy(self.queue, self._obs_buf, observed, is_blocking=True)
        self._proj = np.array(tb.projection(self.intrinsics), dtype=np.float32)
        self._state_version += 1

    def set_joint_targets(self, xy: np.ndarray, xyz: np.ndarray, weight: np.ndarray, point_index: np.ndarray,
                          pairs: np.ndarray, swap_px: float, torso_radius: float, penetration_index: np.ndarray,
                          owner: object = None) -> None:
        """Upload the frame's joint targets for the terms every launch computes (cl/include/joint_term.h).

        xy: (n, 2) detected pixels; xyz: (n, 3) lifted m (NaN rows: not lifted); weight: (n,);
        point_index: (n,) distinct indices into the body's named points; pairs: (m, 2) target
        indices of left/right twins (left first; may match crossed at ``swap_px`` px each);
        torso_radius: m; penetration_index: (8,) named points: 4 arm points, 2 hips, 2 shoulders.
        n = 0: no joint term (E_J2D = E_J3D = 0). owner: who set them
        (:attr:`joint_targets_owner`, so that objectives sharing the scorer upload theirs only when needed)."""
        n, npt = len(point_index), self.point_count
        if n > npt or len(np.unique(point_index)) != n or (n and not 0 <= np.min(point_index) <= np.max(point_index)
                                                          < npt):
            raise ShapeError(f"joint targets need distinct point indices within 0..{npt - 1}, got {point_index}")
        pairs = np.asarray(pairs, np.int32).reshape(-1, 2)
        tgt2d = np.zeros((npt, 4), np.float32)
        tgt3d = np.zeros((npt, 4), np.float32)
        lifted = np.all(np.isfinite(xyz), axis=1) if n else np.zeros(0, bool)
        if n:
            tgt2d[:n] = np.column_stack([xy, weight, point_index])
            tgt3d[:n, :3] = np.where(lifted[:, None], xyz, 0.0)
            tgt3d[:n, 3] = lifted
        cl, q, m = self._cl, self.queue, self._mesh
        cl.enqueue_copy(q, m["tgt2d"], tgt2d)
        cl.enqueue_copy(q, m["tgt3d"], tgt3d)
        if len(pairs):
            cl.enqueue_copy(q, m["pairs"], np.ascontiguousarray(pairs))
        cl.enqueue_copy(q, m["pen"], np.ascontiguousarray(penetration_index, np.int32), is_blocking=True)
        w2 = float(np.sum(weight)) if n else 0.0
        w3 = float(np.sum(np.asarray(weight)[lifted])) if n else 0.0
        intr = self.intrinsics
        self.joint_targets_owner = owner
        self._state_version += 1
        self._joint_args = (np.int32(n), np.int32(len(pairs)), np.int32(n > 0),
                            np.array([intr.fx, intr.fy, intr.cx, intr.cy], np.float32),
                            np.array([swap_px, 1.0 / w2 if w2 > 0 else 0.0, 1.0 / w3 if w3 > 0 else 0.0, torso_radius],
                                     np.float32))

    @property
    def tile_box(self) -> TileBox | None:
        """The (clipped) box of the current observation, or None before the first."""
        return self._tile_box

    @property
    def observed(self) -> np.ndarray | None:
        """The current observation tile (TH, TW) float32 m, 0 = none."""
        return self._observed

    @property
    def last_timings(self) -> dict[str, float]:
        """The split of the last launch in s: upload_s, kernel_s, readback_s (OpenCL event times)
        and wall_s (enqueue to results); read from the events only when asked, which costs
        ~20 us a launch ({} before the first)."""
        if self._last_launch is None:
            return {}
        up, run, down, wall = self._last_launch

        def dur(ev) -> float:
            return 0.0 if ev is None else (ev.profile.end - ev.profile.start) * 1e-9

        return {"upload_s": dur(up), "kernel_s": dur(run), "readback_s": sum(dur(e) for e in down), "wall_s": wall}

    # ------------------------------------------------------------------ per generation
    def transforms(self, h: np.ndarray) -> np.ndarray:
        """Validated poses (P, 36) -> bone transforms (P, B, 3, 4) float32 (one numpy call)."""
        h = as_poses(h)
        if len(h) == 0:
            return np.zeros((0, self.defines["NB"], 3, 4), np.float32)
        return skinning_transforms(self.body.rig, h).astype(np.float32)

    def evaluate(self, h: np.ndarray, render: bool = True, points: bool = True) -> Evaluation:
        """One launch for poses h (P, 36), forward kinematics on the device: the depth term's
        sums (float64, m summed over observed tile pixels) and counts (:data:`COUNT_NAMES`), the
        body's named points (in ``body.point_names`` order) and the joint and penetration terms
        (:class:`Evaluation`). render=False: no depth term (sums and counts 0; no observation
        needed); points=False: the points are not read back (None)."""
        poses = np.ascontiguousarray(as_poses(h), np.float32)
        sums, counts, (named, terms), _ = self._launch(poses, fk=True, write_tiles=False, render=render,
                                                       want_points=points)
        return Evaluation(sums, counts, named, terms)

    def score(self, h: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Sums and counts of :meth:`evaluate`."""
        result = self.evaluate(h, points=False)
        return result.sums, result.counts

    def score_transforms(self, transforms: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """As :meth:`score`, from precomputed bone transforms (P, B, 3, 4) (camera frame)."""
        transforms = np.asarray(transforms, np.float32)
        nb = self.defines["NB"]
        if transforms.ndim != 4 or transforms.shape[1:] != (nb, 3, 4):
            raise ShapeError(f"transforms have shape {transforms.shape}, expected (P, {nb}, 3, 4)")
        if not np.all(np.isfinite(transforms)):
            raise ShapeError("bone transforms contain non-finite values")
        sums, counts, _, _ = self._launch(transforms, fk=False, write_tiles=False, render=True)
        return sums, counts

    def render_and_score(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Debug path: rendered depth tiles (P, TH, TW) float32 m (0 = background), sums, counts."""
        poses = np.ascontiguousarray(as_poses(h), np.float32)
        sums, counts, _, tiles = self._launch(poses, fk=True, write_tiles=True, render=True)
        return tiles, sums, counts

    def device_transforms(self, h: np.ndarray) -> np.ndarray:
        """Bone transforms (P, B, 3, 4) float32 as the device's forward kinematics computes them
        for poses h (P, 36) (debug path; :meth:`transforms` is the numpy oracle)."""
        poses = np.ascontiguousarray(as_poses(h), np.float32)
        self._launch(poses, fk=True, write_tiles=True, render=False)
        bones = np.empty((len(poses), self.defines["NB"], 3, 4), np.float32)
        if len(poses):
            self._cl.enqueue_copy(self.queue, bones, self._bones_out_buf, is_blocking=True)
        return bones

    def render(self, h: np.ndarray) -> np.ndarray:
        """Rendered depth tiles (P, TH, TW) float32 m, 0 = background (debug path)."""
        return self.render_and_score(h)[0]

    def _set_args(self, kernel, key: tuple[bool, bool], render: bool) -> None:
        """Set ``kernel``'s arguments unless they are already those of the current state (setting
        two dozen arguments costs about 0.1 ms, as much as a tenth of a coarse generation)."""
        state = (self._state_version, render)
        if self._args_state.get(key) == state:
            return
        m = self._mesh
        observation = self._obs_buf if self._obs_buf is not None else m["no_observation"]
        proj = self._proj if self._obs_buf is not None else np.zeros(4, np.float32)
        write_tiles = key[0]
        kernel.set_args(self._input_buf, m["steps"], m["links"], m["bone_data"], m["point_bone"], m["point_rest"],
                        m["rest"], m["idx"], m["w"], m["tris"], observation, proj, np.float32(self.threshold),
                        np.int32(render), m["tgt2d"], m["tgt3d"], m["pairs"], m["pen"], *self._joint_args,
                        self._results_buf, self._points_buf,
                        self._tiles_buf if write_tiles else self._results_buf,
                        self._bones_out_buf if write_tiles else self._results_buf)
        self._args_state[key] = state

    def _launch(self, data: np.ndarray, fk: bool, write_tiles: bool, render: bool, want_points: bool = True):
        """One launch for P particles: data is poses (P, 36) (fk) or transforms (P, NB, 3, 4),
        float32. Returns sums, counts, (points (P, NPT, 3) or None, terms) or None, tiles or
        None. Lean: one upload, one poisoning fill, the kernel, one read of the packed results
        (plus the points or tiles when asked), one wait."""
        cl = self._cl
        if render and self._obs_buf is None:
            raise ConfigError("call set_observation(depth, box) before scoring")
        p = len(data)
        npt = self.point_count
        if p == 0:
            self._last_launch = (None, None, [], 0.0)
            empty = np.zeros((0, self.th, self.tw), np.float32) if write_tiles else None
            return (np.zeros(0), {k: np.zeros(0, np.int64) for k in COUNT_NAMES},
                    (np.zeros((0, npt, 3)), {k: np.zeros(0) for k in TERM_NAMES}) if fk else None, empty)
        t1 = time.perf_counter()
        self._ensure_capacity(p, write_tiles)
        q = self.queue
        up = cl.enqueue_copy(q, self._input_buf, data, is_blocking=False)
        cl.enqueue_fill_buffer(q, self._results_buf, np.float32(np.nan), 0, p * 32)
        read_points = fk and want_points
        if read_points:
            cl.enqueue_fill_buffer(q, self._points_buf, np.float32(np.nan), 0, p * npt * 16)
        if write_tiles:
            cl.enqueue_fill_buffer(q, self._tiles_buf, np.float32(np.nan), 0, p * self.tw * self.th * 4)
        kernel = self._kernel(write_tiles, fk)
        self._set_args(kernel, (write_tiles, fk), render)
        wg = self.local_size
        run = cl.enqueue_nd_range_kernel(q, kernel, (p * wg,), (wg,))
        results = self._results_host[:p]
        down = [cl.enqueue_copy(q, results, self._results_buf, is_blocking=False)]
        points = tiles = None
        if read_points:
            points = np.empty((p, npt, 4), np.float32)
            down.append(cl.enqueue_copy(q, points, self._points_buf, is_blocking=False))
        if write_tiles:
            tiles = np.empty((p, self.th, self.tw), np.float32)
            down.append(cl.enqueue_copy(q, tiles, self._tiles_buf, is_blocking=False))
        cl.wait_for_events(down)
        self._last_launch = (up, run, down, time.perf_counter() - t1)
        packed = results[:, 1:5]
        if not np.all(np.isfinite(packed)):  # a result the kernel did not write: -1, as a poisoned count
            packed = np.where(np.isfinite(packed), packed, -1.0)
        counts = {k: packed[:, i].astype(np.int64) for i, k in enumerate(COUNT_NAMES)}
        extra = None
        if fk:
            extra = (None if points is None else points[..., :3].astype(np.float64),
                     {k: results[:, 5 + i].astype(np.float64) for i, k in enumerate(TERM_NAMES)})
        return results[:, 0].astype(np.float64), counts, extra, tiles
