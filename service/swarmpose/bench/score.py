"""Benchmarks. ``bench_score``: the OpenCL particle scorer against a per-hypothesis CPU baseline.

Both sides score the same P hypotheses against the same observation in the same run:

* OpenCL: one upload of the poses, one launch (forward kinematics, named points, skinning,
  rasterising and scoring on the device), one read-back per generation
  (:meth:`swarmpose.gpu.scorer.ParticleScorer.evaluate`: everything the tracker's objective
  launches); with ``host_fk=True`` the older path: the numpy FK on the host, its transforms
  uploaded (:meth:`~swarmpose.gpu.scorer.ParticleScorer.score_transforms`);
* baseline: the same FK call, then per hypothesis numpy LBS, an Open3D ``RaycastingScene``
  built from the posed mesh, the rays of the tile pixels of B cast, and the float64 numpy
  score (:mod:`swarmpose.gpu.reference`).

Times are medians over ``repeats`` generations after warm-up. Run it as
``python -m swarmpose.bench.score [particles] [TWxTH] [body]``.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from swarmpose.body.kinematics import linear_blend_skinning, skinning_transforms
from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.gpu.context import describe
from swarmpose.gpu.reference import raycast_tiles, reference_score
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.gpu.tile import box_around
from swarmpose.sim.render import Renderer, Room
from swarmpose.tracking.config import tracker_default

TRUE_POSE_DISTANCE = 3.0  # m in front of the camera
FACING = (0.0, 1.0, 0.0, 0.0)


def _scene(body, rng: np.random.Generator, particles: int, intr: Intrinsics):
    """Observation depth (H, W) of a true pose in a room, with noise, and P hypotheses around it."""
    h_true = body.rest_pose((0.0, 0.1, TRUE_POSE_DISTANCE), FACING)
    room = Room(floor_point=np.array([0.0, 1.0, 0.0]), floor_normal=np.array([0.0, -1.0, 0.0]),
                wall_point=np.array([0.0, 0.0, 4.5]), wall_normal=np.array([0.0, 0.0, -1.0]))
    depth = Renderer(intr).render(body.pose(h_true[None])[0], body.triangles, room)[0]
    depth = (depth + rng.normal(0.0, 0.005, depth.shape) * (depth > 0)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.05] = 0.0
    return h_true, hypotheses_around(h_true, rng, particles), depth


def hypotheses_around(h_true: np.ndarray, rng: np.random.Generator, particles: int) -> np.ndarray:
    """P poses (P, 36) scattered about ``h_true`` (36,): the joint angles by N(0, 0.15 rad),
    the root position by N(0, 3 cm), the root rotation kept (a generation of a search)."""
    h = np.tile(h_true, (particles, 1))
    h[:, 7:] += rng.normal(0.0, 0.15, (particles, 29))
    h[:, :3] += rng.normal(0.0, 0.03, (particles, 3))
    return h


def _median(rows: list[dict], key: str) -> float:
    return float(np.median([r[key] for r in rows]))


def bench_score(particles: int = 64, resolution: tuple[int, int] = (64, 64), body: str = "builtin",
                shape: str | None = None, repeats: int = 20, device=None, lod: int = 1500,
                baseline_repeats: int | None = None, warmup: int = 3, seed: int = 0, host_fk: bool = False) -> dict:
    """Hypotheses per second of the OpenCL scorer and of the CPU baseline, and where time goes.

    particles: P hypotheses per generation; resolution: tile (TW, TH) pixels over the box B;
    body / shape: as ``--body`` / ``--shape``; lod: tracking-LOD triangles; device: an
    OpenCL device spec (None or "": the default device). Returns a dict with
    ``hypotheses_per_s``, ``baseline_hypotheses_per_s``, ``ratio``, ``particles``,
    ``resolution``, ``triangles``, ``vertices``, ``device``, ``split_ms`` (per generation:
    host_fk (0 unless ``host_fk``), upload, kernel, readback, sync = wall time not covered by
    those, total),
    ``kernel_hypotheses_per_s`` (kernel time only), ``baseline_split_ms`` and
    ``max_sum_difference`` (largest relative difference of the two sides' sums).
    """
    rng = np.random.default_rng(seed)
    intr = Intrinsics.kinect_v1()
    model = load_body(body, shape).tracking_lod(lod)
    h_true, h, depth = _scene(model, rng, int(particles), intr)
    box = box_around(intr.project(model.pose(h_true[None])[0]), margin=0.15)

    scorer = ParticleScorer(model, intr, tuple(resolution), threshold=tracker_default("threshold_m"), context=device)
    scorer.set_observation(depth, box)
    rows = []
    for i in range(warmup + repeats):
        t0 = time.perf_counter()
        if host_fk:
            transforms = scorer.transforms(h)
            t1 = time.perf_counter()
            sums, _ = scorer.score_transforms(transforms)
        else:
            t1 = t0
            sums = scorer.evaluate(h).sums
        t2 = time.perf_counter()
        if i >= warmup:
            tm = scorer.last_timings
            rows.append({"host_fk": t1 - t0, "upload": tm["upload_s"], "kernel": tm["kernel_s"],
                         "readback": tm["readback_s"],
                         "sync": tm["wall_s"] - tm["upload_s"] - tm["kernel_s"] - tm["readback_s"],
                         "total": t2 - t0})
    split = {k: 1e3 * _median(rows, k) for k in rows[0]}

    rays = scorer.tile_box.rays(intr)
    observed = scorer.observed
    base_rows = []
    for i in range(1 + (baseline_repeats or max(3, repeats // 4))):
        t0 = time.perf_counter()
        transforms = skinning_transforms(model.rig, h)
        t1 = time.perf_counter()
        base_sums = np.empty(len(h))
        for p in range(len(h)):  # the per-hypothesis CPU path being replaced
            verts = linear_blend_skinning(model.vertices, model.skin_indices, model.skin_weights,
                                          transforms[p:p + 1])
            tiles = raycast_tiles(verts, model.triangles, rays)
            base_sums[p] = reference_score(tiles, observed, scorer.threshold)[0][0]
        t2 = time.perf_counter()
        if i >= 1:
            base_rows.append({"host_fk": t1 - t0, "per_hypothesis": t2 - t1, "total": t2 - t0})
    base_split = {k: 1e3 * _median(base_rows, k) for k in base_rows[0]}

    rate = particles / (split["total"] * 1e-3)
    base_rate = particles / (base_split["total"] * 1e-3)
    scale = np.maximum(np.abs(base_sums), 1e-9)
    return {
        "hypotheses_per_s": rate,
        "baseline_hypotheses_per_s": base_rate,
        "ratio": rate / base_rate,
        "kernel_hypotheses_per_s": particles / (split["kernel"] * 1e-3),
        "particles": int(particles),
        "resolution": [int(resolution[0]), int(resolution[1])],
        "triangles": int(len(model.triangles)),
        "vertices": int(len(model.vertices)),
        "bones": int(len(model.bone_names)),
        "body": model.name,
        "fk": "host" if host_fk else "device",
        "device": describe(scorer.device),
        "local_size": scorer.local_size,
        "repeats": int(repeats),
        "split_ms": split,
        "baseline_split_ms": base_split,
        "max_sum_difference": float(np.max(np.abs(sums - base_sums) / scale)),
        "box": list(scorer.tile_box.box),
    }


def format_bench(result: dict) -> str:
    """A few human-readable lines for a :func:`bench_score` result."""
    s = result["split_ms"]
    b = result["baseline_split_ms"]
    tw, th = result["resolution"]
    return "\n".join([
        f"scorer: {result['particles']} particles, {tw}x{th} tile, FK on the {result['fk']}, {result['body']} "
        f"({result['triangles']} triangles, {result['vertices']} vertices), {result['device']}",
        f"OpenCL   {result['hypotheses_per_s']:10.0f} hypotheses/s   "
        f"(kernel only {result['kernel_hypotheses_per_s']:.0f}/s)",
        f"baseline {result['baseline_hypotheses_per_s']:10.0f} hypotheses/s   (Open3D ray casting per hypothesis)",
        f"ratio    {result['ratio']:10.1f}x",
        f"per generation (ms): host FK {s['host_fk']:.2f}, upload {s['upload']:.3f}, kernel {s['kernel']:.2f}, "
        f"read-back {s['readback']:.3f}, sync {s['sync']:.3f}, total {s['total']:.2f}; "
        f"baseline FK {b['host_fk']:.2f} + per-hypothesis {b['per_hypothesis']:.1f}",
        f"largest relative difference of the sums: {result['max_sum_difference']:.2e}",
    ])


if __name__ == "__main__":
    args = sys.argv[1:]
    kw: dict = {}
    if args:
        kw["particles"] = int(args[0])
    if len(args) > 1:
        kw["resolution"] = tuple(int(x) for x in args[1].lower().split("x"))
    if len(args) > 2:
        kw["body"] = args[2]
    print(format_bench(bench_score(**kw)))
