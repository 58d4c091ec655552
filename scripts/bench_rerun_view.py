"""Per-frame cost of the rerun viewer sink (``--view`` / ``--rrd``), in ms.

Logs the frames of a sequence folder with the frame messages of a run over it
(``poses.jsonl``) into an ``.rrd`` file, ``--repeat`` times over, and prints the median and
95th percentile of :meth:`RerunSink.frame` and of its parts (depth point cloud, JPEG image),
plus the file's size per frame::

    swarmpose synth --motion builtin:wave --frames 30 --out /tmp/wave
    swarmpose track /tmp/wave --out /tmp/wave-out --particles 16 --generations 3 --no-overlay
    python scripts/bench_rerun_view.py /tmp/wave /tmp/wave-out --repeat 5
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from swarmpose.publish.rerun_files import read_messages
from swarmpose.publish.rerun_view import DEPTH_STEP, depth_points, open_view_sink
from swarmpose.sources.base import Frame
from swarmpose.sources.registry import open_source


def percentiles(values: list[float]) -> str:
    return f"median {np.median(values):.2f} ms, p95 {np.percentile(values, 95):.2f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sequence", help="a sequence folder")
    parser.add_argument("run", help="the folder with poses.jsonl of a run over it")
    parser.add_argument("--repeat", type=int, default=5, help="log the sequence this many times")
    parser.add_argument("--depth-step", type=int, default=DEPTH_STEP)
    args = parser.parse_args()
    with open_source(args.sequence) as source:
        frames = [f for f in source if isinstance(f, Frame)]
    messages = {m["frame"]: m for m in read_messages(Path(args.run) / "poses.jsonl")}
    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "bench.rrd"
        sink = open_view_sink("camera0", rrd=str(rrd), depth_step=args.depth_step)
        whole, depth, image = [], [], []
        n = 0
        for _ in range(args.repeat):
            for frame in frames:
                message = dict(messages[frame.index], frame=n)
                start = time.perf_counter()
                sink.frame(message, frame)
                whole.append(1e3 * (time.perf_counter() - start))
                start = time.perf_counter()
                points, _ = depth_points(frame, args.depth_step)
                depth.append(1e3 * (time.perf_counter() - start))
                start = time.perf_counter()
                sink.rr.Image(frame.color, color_model="RGB").compress(jpeg_quality=85)
                image.append(1e3 * (time.perf_counter() - start))
                n += 1
        start = time.perf_counter()
        sink.close()
        closing = time.perf_counter() - start
        size = rrd.stat().st_size
    w, h = frames[0].size
    print(f"{n} frames of {w}x{h}, depth step {args.depth_step} ({len(points)} points in the last frame)")
    print(f"RerunSink.frame: {percentiles(whole)}")
    print(f"  of which depth point cloud: {percentiles(depth)}; JPEG of the colour image: {percentiles(image)}")
    print(f"close (flush to the file): {closing * 1e3:.0f} ms; .rrd {size / n / 1e3:.0f} kB per frame")


if __name__ == "__main__":
    main()
