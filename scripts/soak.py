"""Soak test of the daemon (issue 16): ``swarmpose serve --loop`` on a small synthetic folder
until ``--frames`` frames were processed, watched from outside.

* resident memory (RSS) of the daemon at its first frame ("start"), at ``--warmup`` frames and at
  the end, and the largest seen; the growth from warm-up to the end must stay under 5 %;
* frames processed (the worker's own counter, ``frames.published`` of its last status message)
  against frames published (a plain zenoh subscriber on loopback counting the frame messages);
* the daemon's log scanned for errors and tracebacks, and its exit status after SIGTERM.

usage: .venv/bin/python scripts/soak.py [--frames 10000] [--warmup 500] [--particles 8]
       [--generations 4] [--tile 16x16] [--max-people 1] [--work DIR] [-- MORE SERVE FLAGS]
Prints the samples as they come, then one JSON report; exits 1 when a check fails.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from daemon_probe import Watcher, log_problems, rss_bytes, serve, session, stop, synth_folder

from swarmpose.cli.demo import free_local_port
from swarmpose.core.polling import wait_until

MAX_GROWTH = 0.05
CAMERA = "soak"


def parse(argv: list[str] | None) -> tuple[argparse.Namespace, list[str]]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--frames", type=int, default=10_000, help="frames processed before the daemon is stopped")
    p.add_argument("--warmup", type=int, default=500, help="frames after which the warm-up RSS is taken")
    p.add_argument("--particles", default="8")
    p.add_argument("--generations", default="4")
    p.add_argument("--tile", default="16x16")
    p.add_argument("--max-people", default="1")
    p.add_argument("--seq-frames", type=int, default=90, help="length of the synthetic folder served in a loop")
    p.add_argument("--work", type=Path, default=Path("/tmp/swarmpose-soak"), help="folder of the sequence and log")
    p.add_argument("--timeout-s", type=float, default=3600.0, help="give up after this many seconds")
    args, more = p.parse_known_args(argv)
    return args, [m for m in more if m != "--"]


def main(argv: list[str] | None = None) -> int:
    args, more = parse(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    seq = synth_folder(args.work / "seq", args.seq_frames)
    log = args.work / "serve.log"
    endpoint = f"tcp/127.0.0.1:{free_local_port()}"
    listener = session(listen=endpoint)            # the subscriber is there before the daemon
    watcher = Watcher(CAMERA)
    subscribers = watcher.attach(listener)
    flags = ["--connect", endpoint, "--no-multicast", "--particles", args.particles, "--generations",
             args.generations, "--tile", args.tile, "--max-people", args.max_people, *more]
    started = time.monotonic()
    proc = serve(seq, CAMERA, log, *flags)
    marks: dict[str, dict] = {}
    samples: list[tuple[float, int, int]] = []     # (s since start, frames processed, RSS bytes)
    peak = 0
    try:
        while proc.poll() is None and time.monotonic() - started < args.timeout_s:
            time.sleep(1.0)
            status = watcher.last_status
            processed = status["frames"]["published"] if status else 0
            rss = rss_bytes(proc.pid)
            peak = max(peak, rss)
            samples.append((round(time.monotonic() - started, 1), processed, rss))
            for name, at in (("start", 1), ("warmup", args.warmup), ("end", args.frames)):
                if name not in marks and processed >= at:
                    marks[name] = {"frames": processed, "rss_mib": round(rss / 2**20, 1),
                                   "elapsed_s": round(time.monotonic() - started, 1)}
            if len(samples) % 30 == 1:
                print(f"{samples[-1][0]:7.1f} s  {processed:6d} frames  RSS {rss / 2**20:7.1f} MiB  "
                      f"fps {status['fps'] if status else 0:.1f}", flush=True)
            if "end" in marks:
                break
        exit_status = stop(proc)
        wait_until(lambda: (watcher.last_status or {}).get("state") == "stopping", 10.0, 0.1)
        time.sleep(1.0)                            # the frames still on the way
    finally:
        if proc.poll() is None:
            proc.kill()
        del subscribers
        listener.close()
    report = summarise(args, marks, samples, peak, watcher, exit_status, log, time.monotonic() - started)
    (args.work / "report.json").write_text(json.dumps(report, indent=1))
    rows = "".join(f"{t},{n},{r}\n" for t, n, r in samples)
    (args.work / "rss.csv").write_text("elapsed_s,frames,rss_bytes\n" + rows)
    print(json.dumps(report))
    return 0 if report["passed"] else 1


def summarise(args, marks: dict, samples: list, peak: int, watcher: Watcher, exit_status: int, log: Path,
              seconds: float) -> dict:
    """The report: RSS marks and growth, frames processed vs received, log problems, checks."""
    last = watcher.last_status or {"frames": {}, "errors": [], "state": "none"}
    processed = last["frames"].get("published", 0)
    growth = None
    if "warmup" in marks and "end" in marks:
        growth = marks["end"]["rss_mib"] / marks["warmup"]["rss_mib"] - 1.0
    problems = log_problems(log)
    checks = {"frames_reached": "end" in marks,
              "rss_growth_below_5pct": growth is not None and growth < MAX_GROWTH,
              "every_frame_received": processed > 0 and watcher.frames == processed and watcher.bad == 0,
              "no_error_in_log": not problems and not last["errors"],
              "exit_0": exit_status == 0}
    return {"command": "serve " + " ".join(["--loop", "--particles", args.particles, "--generations",
                                             args.generations, "--tile", args.tile, "--max-people",
                                             args.max_people]),
            "seconds": round(seconds, 1), "rss": marks, "rss_peak_mib": round(peak / 2**20, 1),
            "rss_growth_after_warmup": None if growth is None else round(growth, 4),
            "frames": {"processed": processed, "received_by_subscriber": watcher.frames,
                       "malformed": watcher.bad, "worker": last["frames"]},
            "final_state": last["state"], "status_errors": last["errors"], "log_problems": problems[:20],
            "exit_status": exit_status, "checks": checks, "passed": all(checks.values())}


if __name__ == "__main__":
    sys.exit(main())
