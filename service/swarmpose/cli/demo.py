"""``swarmpose demo`` (``make demo``): the whole service on embedded defaults, nothing but the repository.

1. synthesise a short sequence with the built-in body and the built-in ``wave`` motion;
2. start the worker on it, publishing over zenoh in peer mode on a free local port
   (multicast scouting off, so nothing leaves the machine) and recording the replay files;
3. start a separate subscriber process (``python -m swarmpose subscribe``) that prints the
   first poses it receives;
4. print Δ and A(t) against the ground truth, fps, latency and where the outputs are.

It exits 1 when the subscriber got fewer frames than it waited for or a replay file could not
be written (the other outputs are kept).

Every frame is tracked (replay hand-overs: none dropped), so Δ covers the whole sequence.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path

from swarmpose.cli.common import DEFAULTS, positive_int, quiet
from swarmpose.core.errors import PublishError
from swarmpose.core.settings import build
from swarmpose.pipeline.config import ServiceConfig

DEMO_DIR = Path("demo-output")
SUBSCRIBER_FRAMES = 5
CONNECT_TIMEOUT_S = 60.0
"""How long the demo waits for its subscriber process to start and connect (s): about 2 s on an idle
machine; a loaded one (four processes on two cores) took more than 20."""


def free_local_port() -> int:
    """A TCP port on 127.0.0.1 nobody listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _relay(stream, prefix: str, lines: list[str]) -> None:
    for line in stream:
        lines.append(line.rstrip("\n"))
        sys.stdout.write(prefix + line)
        sys.stdout.flush()


def start_subscriber(endpoint: str, camera: str, count: int) -> tuple[subprocess.Popen, threading.Thread, list[str]]:
    """A ``python -m swarmpose subscribe`` process connected to ``endpoint``; its lines are echoed
    with a ``subscriber |`` prefix and kept in the returned list."""
    proc = subprocess.Popen([sys.executable, "-m", "swarmpose", "subscribe", "--camera", camera, "--connect",
                             endpoint, "--no-multicast", "--count", str(count), "--timeout", "300"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    lines: list[str] = []
    relay = threading.Thread(target=_relay, args=(proc.stdout, "  subscriber | ", lines), daemon=True)
    relay.start()
    return proc, relay, lines


def wait_for_subscriber(zenoh_sink, lines: list[str], timeout_s: float) -> bool:
    """True once the subscriber says it listens and the worker's frame publisher matches its
    subscription (so no frame is published before the subscriber can get it)."""
    from swarmpose.core.polling import wait_until

    return wait_until(lambda: zenoh_sink.frames_subscribed() and any(line.startswith("listening on")
                                                                     for line in lines), timeout_s, 0.1)


def run_demo(sequence: Path, out: Path, particles: int, generations: int, quiet: bool, frames: int) -> int:
    """Serve ``sequence`` (``frames`` long) over zenoh with a subscriber beside it; print the results."""
    from swarmpose.pipeline.service import build_worker, format_summary, run_summary

    endpoint = f"tcp/127.0.0.1:{free_local_port()}"
    config = build(ServiceConfig, {"source": f"folder:{sequence}", "camera_id": "demo", "zenoh_mode": "peer",
                                   "listen": (endpoint,), "multicast": False, "particles": particles,
                                   "generations": generations, "record": str(out), "status_period_s": 1.0})
    with ExitStack() as stack:
        worker, parts, zenoh = build_worker(config, stack, replay=True, progress=not quiet)
        count = min(SUBSCRIBER_FRAMES, frames)
        proc, relay, lines = start_subscriber(endpoint, config.camera_id, count)
        try:
            if not wait_for_subscriber(zenoh, lines, CONNECT_TIMEOUT_S):
                raise PublishError(f"the subscriber did not connect to {endpoint} within {CONNECT_TIMEOUT_S:g} s")
            print(f"serving {sequence} on zenoh (peer, {endpoint}, keys swarmpose/demo/...); "
                  f"the subscriber prints the first {count} poses it receives:", flush=True)
            started = time.monotonic()
            stats = worker.run()
            seconds = time.monotonic() - started
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            relay.join(5)
    result = run_summary(parts, stats, seconds, worker)
    received = sum(1 for line in lines if " frame " in line)
    print(f"the subscriber received {received} frames (exit status {proc.returncode})")
    print(format_summary(result))
    print(f"replay outputs in {out}/ (poses.jsonl: the frame messages; poses.csv; poses.bvh; overlay.mp4)")
    return 0 if proc.returncode == 0 and received >= count and not worker.sink_errors else 1


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job on embedded defaults: synthesise a short sequence, serve it over zenoh with a
    subscriber beside it, report Δ, A(t), fps, latency and the replay outputs."""
    from swarmpose.body.loader import load_body
    from swarmpose.cli.synth import print_synth_summary
    from swarmpose.motion.builtin import builtin_motion
    from swarmpose.sim.synth import SynthConfig, synthesize

    body = load_body("builtin", "default")
    config = SynthConfig(frames=args.frames, fps=30.0, seed=0)
    motion = builtin_motion("wave", config.frames, config.fps)
    out = Path(args.out)
    summary = synthesize(body, motion, out, config, description={"motion_spec": "builtin:wave"},
                         progress=not quiet(args))
    print_synth_summary(summary, body)
    print(f"tracking it with the service (hybrid objective, simulated 2D joints, {args.particles} particles x "
          f"{args.generations} generations per frame) ...")
    return run_demo(out, out.parent / "replay", args.particles, args.generations, quiet(args), args.frames)


def add_demo_command(sub: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    """Register ``demo``."""
    p = sub.add_parser("demo", parents=[common], formatter_class=DEFAULTS,
                       help="the main job on built-in defaults (needs no files)")
    p.add_argument("--out", default=str(DEMO_DIR / "sequence"), help="where the demo writes its sequence")
    p.add_argument("--frames", type=positive_int, default=30, help="frames to synthesise and track")
    p.add_argument("--particles", type=positive_int, default=64, help="PSO particles per generation")
    p.add_argument("--generations", type=positive_int, default=64, help="PSO generations per frame")
    p.set_defaults(func=cmd_demo)
