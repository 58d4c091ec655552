"""The OpenCL particle scorer on several devices of one machine, in the same run.

What a user with a GPU gains over PoCL on the same machine's CPU cores: each device scores
the same poses against the same observation (the scene of ``swarmpose bench score``: P
hypotheses about a rest pose 3 m away), generation after generation, for a sweep of P,
tiles and work-group sizes; medians over repeats after warm-up; the sums of every device
compared with the first device's.

Two steps, so that the measuring machine needs numpy and pyopencl alone (Open3D, which
decimates the tracking LOD and renders the observation, may be missing there):

    .venv/bin/python scripts/bench_devices.py prepare SCENE.pkl [--body builtin|makehuman:DIR]
        [--lod 1500]
    python scripts/bench_devices.py measure SCENE.pkl [SCENE.pkl ...] --devices nvidia,pocl
        [--particles 64,256,1024,4096] [--tiles 64x64,32x32] [--local-sizes 0,32,128]
        [--repeats 20] [--json OUT.json]

A device is a ``--device`` spec (``nvidia``, ``pocl``, ``gpu``, ``0:0``), optionally with its
own local sizes (``nvidia@0/32/128``); a local size of 0 is the scorer's own choice (1 on
CPUs, 64 elsewhere). A configuration that a device refuses
(too little local memory, a failed build) is recorded with its error and the sweep goes on.
The JSON is rewritten after every configuration, so a run cut short keeps what it measured.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from swarmpose.core.errors import SwarmposeError
from swarmpose.core.settings import parse_size

SCENE_VERSION = 1


def prepare(path: Path, body: str, lod: int, seed: int = 0) -> dict:
    """Write the scene of ``swarmpose bench score`` (the tracking LOD of ``body``, the true
    pose (36,), the observed depth (H, W) in m, the tile box) to ``path`` (a pickle: our
    own dataclasses, read back by :func:`measure` on the measuring machine)."""
    from swarmpose.bench.score import _scene
    from swarmpose.body.loader import load_body
    from swarmpose.core.camera import Intrinsics
    from swarmpose.gpu.tile import box_around

    intr = Intrinsics.kinect_v1()
    model = load_body(body, None).tracking_lod(lod)
    h_true, _, depth = _scene(model, np.random.default_rng(seed), 1, intr)
    box = box_around(intr.project(model.pose(h_true[None])[0]), margin=0.15)
    scene = {"version": SCENE_VERSION, "body": model, "intrinsics": intr, "h_true": h_true,
             "depth": depth, "box": box, "spec": body, "lod": lod}
    path.write_bytes(pickle.dumps(scene))
    return {"path": str(path), "body": model.name, "triangles": len(model.triangles),
            "vertices": len(model.vertices)}


def _load(path: Path) -> dict:
    scene = pickle.loads(path.read_bytes())  # noqa: S301 - our own file, written by prepare()
    if scene.get("version") != SCENE_VERSION:
        raise SwarmposeError(f"{path}: scene version {scene.get('version')}, expected {SCENE_VERSION}; "
                             "write it again with 'bench_devices.py prepare'")
    return scene


def _time_scorer(scorer, h: np.ndarray, warmup: int, repeats: int) -> tuple[dict, np.ndarray]:
    """Median ms per generation (wall: upload to results; kernel: its event time) of
    ``scorer.evaluate(h)`` and the last generation's sums (P,)."""
    walls, kernels = [], []
    sums = np.zeros(len(h))
    for i in range(warmup + repeats):
        t0 = time.perf_counter()
        sums = scorer.evaluate(h).sums
        wall = time.perf_counter() - t0
        if i >= warmup:
            walls.append(wall)
            kernels.append(scorer.last_timings["kernel_s"])
    return {"wall_ms": 1e3 * float(np.median(walls)), "kernel_ms": 1e3 * float(np.median(kernels))}, sums


def measure(scenes: list[Path], devices: list[str], particles: list[int], tiles: list[tuple[int, int]],
            local_sizes: list[int], repeats: int, warmup: int, out: Path | None, seed: int = 0) -> list[dict]:
    """One row per (scene, device, tile, local size, P): hypotheses/s end to end and of the
    kernel alone, the ms split, and ``max_sum_difference`` (largest relative difference of
    the sums from the first device's at the same scene, tile and P). Rows go to ``out``
    (JSON) as they come."""
    from swarmpose.bench.score import hypotheses_around
    from swarmpose.gpu.context import ClContext, describe
    from swarmpose.gpu.scorer import ParticleScorer

    rows: list[dict] = []
    reference: dict[tuple, np.ndarray] = {}
    for scene_path in scenes:
        scene = _load(scene_path)
        poses = {p: hypotheses_around(scene["h_true"], np.random.default_rng(seed), p) for p in particles}
        for device in devices:
            spec, _, own_sizes = device.partition("@")
            sizes = _ints(own_sizes.replace("/", ",")) if own_sizes else local_sizes
            try:
                context = ClContext.for_spec(spec)
            except SwarmposeError as exc:
                rows.append({"scene": scene_path.name, "spec": spec, "error": str(exc)})
                _write(out, rows)
                print(f"{spec}: {exc}", flush=True)
                continue
            for tile in tiles:
                for local in sizes:
                    base = {"scene": scene_path.name, "body": scene["body"].name,
                            "triangles": len(scene["body"].triangles), "device": describe(context.device),
                            "spec": spec, "tile": list(tile), "requested_local_size": local}
                    try:
                        t0 = time.perf_counter()
                        scorer = ParticleScorer(scene["body"], scene["intrinsics"], tile, context=context,
                                                local_size=local or None)
                        scorer.set_observation(scene["depth"], scene["box"])
                        scorer.evaluate(poses[particles[0]])  # builds the program
                        build_s = time.perf_counter() - t0
                    except Exception as exc:  # a device refusing a configuration: recorded, the sweep goes on
                        _refused(out, rows, base, exc)
                        continue
                    for p in particles:
                        try:
                            timing, sums = _time_scorer(scorer, poses[p], warmup, repeats)
                        except Exception as exc:  # e.g. out of resources at a large P
                            _refused(out, rows, {**base, "particles": p}, exc)
                            break
                        key = (scene_path.name, tuple(tile), p)
                        ref = reference.setdefault(key, sums)
                        diff = float(np.max(np.abs(sums - ref) / np.maximum(np.abs(ref), 1e-9)))
                        rows.append({**base, "local_size": scorer.local_size, "particles": p,
                                     "build_s": build_s, **timing,
                                     "hypotheses_per_s": p / (timing["wall_ms"] * 1e-3),
                                     "kernel_hypotheses_per_s": p / (timing["kernel_ms"] * 1e-3),
                                     "max_sum_difference": diff})
                        _write(out, rows)
                        print(_line(rows[-1]), flush=True)
    return rows


def _refused(out: Path | None, rows: list[dict], base: dict, exc: Exception) -> None:
    rows.append({**base, "error": f"{type(exc).__name__}: {exc}"[:4000]})
    _write(out, rows)
    print(f"{base['spec']} tile {base['tile']} wg {base['requested_local_size']}: {rows[-1]['error'][:300]}",
          flush=True)


def _write(out: Path | None, rows: list[dict]) -> None:
    if out is not None:
        out.write_text(json.dumps(rows, indent=1))


def _line(row: dict) -> str:
    return (f"{row['body']:<24} {row['spec']:<7} tile {row['tile'][0]}x{row['tile'][1]} wg {row['local_size']:>3} "
            f"P {row['particles']:>5}: {row['hypotheses_per_s']:>9.0f} hyp/s "
            f"(kernel {row['kernel_hypotheses_per_s']:.0f}),"
            f" wall {row['wall_ms']:.2f} ms, kernel {row['kernel_ms']:.2f} ms, sums {row['max_sum_difference']:.1e}")


def _ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x]


def _tiles(text: str) -> list[tuple[int, int]]:
    return [parse_size(t, "--tiles") for t in text.split(",") if t]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    prep = sub.add_parser("prepare", help="write a scene (needs Open3D)")
    prep.add_argument("scene", type=Path)
    prep.add_argument("--body", default="builtin")
    prep.add_argument("--lod", type=int, default=1500, help="tracking-LOD triangles")
    meas = sub.add_parser("measure", help="time the scorer on each device")
    meas.add_argument("scenes", type=Path, nargs="+")
    meas.add_argument("--devices", default="gpu,pocl")
    meas.add_argument("--particles", default="64,256,1024,4096")
    meas.add_argument("--tiles", default="64x64,32x32")
    meas.add_argument("--local-sizes", default="0")
    meas.add_argument("--repeats", type=int, default=20)
    meas.add_argument("--warmup", type=int, default=3)
    meas.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.step == "measure" and (args.repeats < 1 or args.warmup < 0):
        parser.error("--repeats must be at least 1 and --warmup at least 0")
    try:
        if args.step == "prepare":
            print(json.dumps(prepare(args.scene, args.body, args.lod)))
        else:
            measure(args.scenes, [d for d in args.devices.split(",") if d], _ints(args.particles),
                    _tiles(args.tiles), _ints(args.local_sizes), args.repeats, args.warmup, args.json)
    except SwarmposeError as exc:
        print(f"bench_devices: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
