"""Where the scorer kernel's time goes: the same launch cut short after each stage.

Builds ``cl/score.cl`` with an early return injected after each stage (forward kinematics
and the joint terms; + clearing the z-buffer, skinning and projecting the vertices; + the
triangles' candidate scan; + rasterising; + the reduction = the whole kernel) and times
each build's launches (OpenCL event times, medians) on the scene of ``swarmpose bench
score``: P particles around a rest pose 3 m away. A stage's cost is its time minus the
previous one's. The early-return builds write something each stage computed, so the
compiler cannot drop the work.

    .venv/bin/python scripts/kernel_stages.py [--body builtin|makehuman:DIR] [--tile 64]
        [--triangles 1500] [--particles 64] [--repeats 40] [--scalar]

``--scalar`` measures the one-triangle-at-a-time raster (``vector_raster=False``).
"""

from __future__ import annotations

import argparse

import numpy as np

import swarmpose.gpu.program as program
from swarmpose.bench.score import _scene
from swarmpose.body.loader import load_body
from swarmpose.core.camera import Intrinsics
from swarmpose.gpu.scorer import ParticleScorer
from swarmpose.gpu.tile import box_around

STAGES = ("FK and joint terms", "clear, skin, project", "triangle scan", "raster", "reduce")

# (text in score.cl after which the stage ends, what the early return writes)
CUTS = {
    2: ("    /* one work-item: two passes", "lverts[p % NV].x"),
    3: ("    raster_kept(zbuf, lverts, tris, lkeep, kept);", "(float)kept"),
    4: ("#if WG == 1 && TW % 8 == 0\n    /* 8 pixels", "(float)zbuf[p % NPIX]"),
}
SCALAR_CUTS = {3: ("    for (int k = 0; k < kept; ++k) {", "(float)kept")}


def cut_source(text: str, stage: int, scalar: bool) -> str:
    """score.cl returning right before what follows stage ``stage`` (1-based; 5 = whole)."""
    cuts = {**CUTS, **(SCALAR_CUTS if scalar else {})}
    if stage not in cuts:
        return text
    marker, value = cuts[stage]
    if text.count(marker) != 1:
        raise SystemExit(f"score.cl changed: cannot find the end of stage {stage} ({marker!r})")
    early = f"    store_depth_term(results, p, {value}, (int4)(0));\n    return;\n"
    return text.replace(marker, early + marker)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--body", default="builtin")
    ap.add_argument("--tile", type=int, default=64)
    ap.add_argument("--triangles", type=int, default=1500)
    ap.add_argument("--particles", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=40)
    ap.add_argument("--scalar", action="store_true", help="the one-triangle-at-a-time raster")
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    intr = Intrinsics.kinect_v1()
    model = load_body(args.body, None).tracking_lod(args.triangles)
    h_true, h, depth = _scene(model, rng, args.particles, intr)
    box = box_around(intr.project(model.pose(h_true[None])[0]), margin=0.15)
    read_source = program.read_source
    times = []
    for stage in range(1, len(STAGES) + 1):
        def patched(filename: str, _seen: frozenset = frozenset(), stage: int = stage) -> str:
            text = read_source(filename, _seen)
            return cut_source(text, stage, args.scalar) if filename == "score.cl" else text

        program.read_source = patched
        try:
            scorer = ParticleScorer(model, intr, (args.tile, args.tile), vector_raster=not args.scalar)
            scorer.defines["STAGE"] = stage  # a distinct build per stage
            scorer.set_observation(depth, box)
            kernel = []
            for i in range(args.repeats + 5):
                scorer.evaluate(h, render=stage > 1, points=False)
                if i >= 5:
                    kernel.append(scorer.last_timings["kernel_s"])
        finally:
            program.read_source = read_source
        times.append(1e3 * float(np.median(kernel)))
    print(f"{model.name}, {len(model.triangles)} triangles, {args.tile}x{args.tile} tile, P = {args.particles}, "
          f"{'scalar' if args.scalar else 'vector'} raster; kernel ms per launch (medians of {args.repeats})")
    previous = 0.0
    for name, t in zip(STAGES, times):
        print(f"  {name:<22} {t - previous:6.3f}  (cumulative {t:6.3f})")
        previous = t
    print(f"  whole kernel: {times[-1]:.3f} ms = {args.particles / times[-1] * 1e3:,.0f} hypotheses/s")


if __name__ == "__main__":
    main()
