"""``swarmpose demo`` (``make demo``): the whole service on embedded defaults, nothing but the repository.

1. synthesise a short sequence with the built-in body and the built-in ``wave`` motion;
2. start the worker on it, publishing over zenoh in peer mode on a free local port
   (multicast scouting off, so nothing leaves the machine) and recording the replay files;
3. start a separate subscriber process (``python -m swarmpose.client``) that prints the
   first poses it receives;
4. print Δ and A(t) against the ground truth, fps, latency and where the outputs are.

Every frame is tracked (replay hand-overs: none dropped), so Δ covers the whole sequence.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path

from .errors import PublishError

SUBSCRIBER_FRAMES = 5
CONNECT_TIMEOUT_S = 20.0


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
    """A ``python -m swarmpose.client`` process connected to ``endpoint``; its lines are echoed
    with a ``subscriber |`` prefix and kept in the returned list."""
    proc = subprocess.Popen([sys.executable, "-m", "swarmpose.client", "--camera", camera, "--connect", endpoint,
                             "--no-multicast", "--count", str(count), "--timeout", "300"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    lines: list[str] = []
    relay = threading.Thread(target=_relay, args=(proc.stdout, "  subscriber | ", lines), daemon=True)
    relay.start()
    return proc, relay, lines


def wait_for_subscriber(zenoh_sink, lines: list[str], timeout_s: float) -> bool:
    """True once the subscriber has declared its subscription and the worker's zenoh session sees it."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if zenoh_sink.state()["peers"] > 0 and any(line.startswith("listening on") for line in lines):
            time.sleep(0.3)  # let the subscription's declaration reach the worker
            return True
        time.sleep(0.1)
    return False


def run_demo(sequence: Path, out: Path, particles: int, generations: int, quiet: bool, frames: int) -> int:
    """Serve ``sequence`` (``frames`` long) over zenoh with a subscriber beside it; print the results."""
    from .cli_serve import build_service, format_replay_summary, replay_summary
    from .config import load_config

    endpoint = f"tcp/127.0.0.1:{free_local_port()}"
    config = load_config({"source": f"folder:{sequence}", "camera_id": "demo", "zenoh_mode": "peer",
                          "listen": (endpoint,), "multicast": False, "particles": particles,
                          "generations": generations, "record": str(out), "status_period_s": 1.0}, env={})
    with ExitStack() as stack:
        service = build_service(config, stack, replay=True, progress=not quiet)
        count = min(SUBSCRIBER_FRAMES, frames)
        proc, relay, lines = start_subscriber(endpoint, config.camera_id, count)
        try:
            if not wait_for_subscriber(service.zenoh, lines, CONNECT_TIMEOUT_S):
                raise PublishError(f"the subscriber did not connect to {endpoint} within {CONNECT_TIMEOUT_S:g} s")
            print(f"serving {sequence} on zenoh (peer, {endpoint}, keys swarmpose/demo/...); "
                  f"the subscriber prints the first {count} poses it receives:", flush=True)
            started = time.monotonic()
            stats = service.worker.run()
            seconds = time.monotonic() - started
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            relay.join(5)
    result = replay_summary(service, stats, seconds)
    received = sum(1 for line in lines if " frame " in line)
    print(f"the subscriber received {received} frames (exit status {proc.returncode})")
    print(format_replay_summary(result))
    print(f"replay outputs in {out}/ (poses.jsonl: the frame messages; poses.csv; poses.bvh; overlay.mp4)")
    return 0 if proc.returncode == 0 and received >= count else 1
