#!/usr/bin/env python3
"""Print the poses a swarmpose worker publishes, as they arrive.

    python examples/subscribe.py                               # peer mode, any camera on the LAN
    python examples/subscribe.py --connect tcp/127.0.0.1:7447  # a worker listening there
    python examples/subscribe.py --mode client --connect tcp/zenoh:7447 --camera kinect0

Uses :class:`swarmpose.publish.client.Client` (pip install swarmpose): each frame message is a dict
following protocol/frame.schema.json; 3D joints are metres in the camera frame.
"""

from __future__ import annotations

import argparse
import sys

from swarmpose.publish.client import Client, add_zenoh_options, format_frame, say


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--camera", default="*", help="camera id (default: every camera)")
    parser.add_argument("--count", type=int, default=0,
                        help="stop after this many frames (0 = run until the workers end or Ctrl-C)")
    add_zenoh_options(parser)
    args = parser.parse_args()

    with Client(args.camera, mode=args.mode, connect=args.connect, listen=args.listen,
                multicast=not args.no_multicast, config_file=args.zenoh_config) as client:
        for info in client.info():
            intr = info["intrinsics"]
            size = "no frame yet" if intr is None else f"{intr['width']}x{intr['height']}"
            say(f"worker {info['camera']}: {info['source']} ({size}), body {info['body']['name']}, "
                  f"joints {info['detector']}, {info['opencl_device'] or 'OpenCL device not chosen yet'}")
        client.on_status(lambda s: say(f"status {s['camera']}: {s['state']}, {s['fps']:.1f} fps, latency "
                                       f"{s['latency_ms']['median'] or 0:.0f} ms, source {s['source']['state']}"))
        try:
            for frame in client.frames(count=args.count or None, until_workers_end=True):
                say(format_frame(frame))
            if client.ended:
                say(f"worker {', '.join(sorted(client.ended))} ended")
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
