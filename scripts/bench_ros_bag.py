"""Per-frame cost of the ROS 2 bag sink (``poses_ros2/`` of ``--out``; ``--no-ros-bag`` leaves it out), in ms.

Writes the frame messages of a run (``poses.jsonl``) into a fresh bag ``--repeat`` times over,
each message as it is and with its bodies copied to ``--people`` ids, and prints the median and
95th percentile of :meth:`RosBagSink.frame`, the time of closing and the bag's size per frame;
with ``--depth SEQ`` also with the depth of the sequence's frames (``--ros-depth``), beside the
run's own median tracking time per frame (``timings_ms.total``)::

    swarmpose synth --motion builtin:wave --frames 30 --out /tmp/wave
    swarmpose track /tmp/wave --out /tmp/wave-out --particles 16 --generations 3 --no-overlay
    python scripts/bench_ros_bag.py /tmp/wave-out --repeat 5 --people 2 --depth /tmp/wave
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from swarmpose.publish.ros_bag import RosBagSink
from swarmpose.sources.base import Frame
from swarmpose.sources.registry import open_source


def percentiles(values: list[float]) -> str:
    return f"median {np.median(values):.2f} ms, p95 {np.percentile(values, 95):.2f} ms"


def with_people(message: dict, people: int) -> dict:
    """``message`` with its first body copied to ids 0 .. people - 1."""
    if not message.get("bodies"):
        return message
    return {**message, "bodies": [{**message["bodies"][0], "id": i} for i in range(people)]}


def run(messages: list[dict], frames: list[Frame | None], repeat: int, depth: bool) -> tuple[list[float], float, int]:
    """Per-frame times (ms), the close's time (ms) and the bag's bytes of one bag of every
    message ``repeat`` times over (capture times made increasing)."""
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        sink = RosBagSink(Path(tmp) / "bag", depth=depth)
        for r in range(repeat):
            for k, (message, frame) in enumerate(zip(messages, frames)):
                message = {**message, "capture_ns": (r * len(messages) + k) * 33_333_333}
                start = time.perf_counter()
                sink.frame(message, frame)
                times.append(1000 * (time.perf_counter() - start))
        start = time.perf_counter()
        sink.close()
        closing = 1000 * (time.perf_counter() - start)
        size = sum(p.stat().st_size for p in (Path(tmp) / "bag").iterdir())
    return times, closing, size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="a run's --out folder (its poses.jsonl)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--people", type=int, default=2, help="also with the body copied to this many ids")
    parser.add_argument("--depth", default="", help="the run's sequence: also with its depth images")
    args = parser.parse_args()
    messages = [json.loads(line) for line in (args.out / "poses.jsonl").read_text().splitlines()]
    tracking = [m["timings_ms"].get("total", 0.0) for m in messages if m.get("timings_ms")]
    print(f"{len(messages)} messages x {args.repeat}; the run's tracking: median {np.median(tracking):.1f} ms/frame")
    cases = [("1 person", messages, False), (f"{args.people} people", [with_people(m, args.people)
                                                                       for m in messages], False)]
    frames: list[Frame | None] = [None] * len(messages)
    if args.depth:
        source = open_source(args.depth)
        try:
            by_index = {f.index: f for f in source if isinstance(f, Frame)}
        finally:
            source.close()
        frames = [by_index.get(m["frame"]) for m in messages]
        cases.append(("1 person + depth", messages, True))
    for name, batch, depth in cases:
        times, closing, size = run(batch, frames if depth else [None] * len(batch), args.repeat, depth)
        print(f"{name}: {percentiles(times)} per frame; close {closing:.0f} ms; {size / len(times) / 1024:.1f} "
              "KiB per frame")


if __name__ == "__main__":
    main()
