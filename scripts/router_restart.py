"""Router restart (issue 16): the daemon in client mode publishes through a zenoh router that is
killed (SIGKILL) and restarted on the same port; how long until frames flow again, and what
the daemon's status said meanwhile.

* the router: a Python zenoh session in router mode on ``tcp/127.0.0.1:PORT`` (multicast
  scouting off), in a subprocess (this script run with ``--as-router PORT``);
* the daemon: ``swarmpose serve --zenoh-mode client --connect tcp/127.0.0.1:PORT --loop`` on a
  small synthetic folder, writing each status to ``--health-file`` (readable while the
  router is down, when no status reaches zenoh);
* a subscriber, a client of the same router with swarmpose's zenoh settings (those of
  ``swarmpose.publish.client``), timestamping every frame message.

``--zenoh-config FILE`` (JSON5) goes to both the daemon and the subscriber, e.g. zenoh's own
``connect/retry`` to compare with swarmpose's.

Each cycle: kill the router, wait ``--down-s``, start it again; the recovery time is from the
moment the new router accepts connections to the first frame the subscriber gets. The subscriber
reconnects too: its own reconnection time is reported beside.

usage: .venv/bin/python scripts/router_restart.py [--cycles 5] [--down-s 3] [--zenoh-config FILE] [--work DIR]
       [-- MORE SERVE FLAGS]
Prints one line per cycle and a JSON report (median and max recovery); exits 1 when frames did
not come back within ``--give-up-s`` in some cycle.
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

from daemon_probe import Watcher, serve, session, stop, synth_folder

from swarmpose.cli.demo import free_local_port
from swarmpose.core.polling import wait_until
from swarmpose.publish.zenoh_link import open_session, zenoh_config

CAMERA = "restart"
GOAL_S = 2.0


def run_router(port: int) -> None:
    """The router process: open, say when it accepts connections (monotonic clock), wait to be killed."""
    router = session(mode="router", listen=f"tcp/127.0.0.1:{port}")
    print(f"ready {time.monotonic():.6f}", flush=True)
    try:
        signal.sigwait({signal.SIGTERM, signal.SIGINT})
    finally:
        router.close()


def start_router(port: int) -> tuple[subprocess.Popen, float]:
    """The router subprocess and the monotonic time (s, system-wide clock) it was listening."""
    proc = subprocess.Popen([sys.executable, __file__, "--as-router", str(port)], stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    if not line.startswith("ready "):
        proc.kill()
        raise RuntimeError(f"the router on port {port} did not start: {line!r}")
    return proc, float(line.split()[1])


class HealthLog(threading.Thread):
    """Reads the daemon's health file every ``step`` s: (time, state, zenoh routers, warning, published)."""

    def __init__(self, path: Path, step: float = 0.1):
        super().__init__(daemon=True)
        self.path, self.step = path, step
        self.rows: list[tuple[float, str, int, str, int]] = []
        self.done = threading.Event()

    def run(self) -> None:
        while not self.done.wait(self.step):
            try:
                s = json.loads(self.path.read_text(encoding="utf-8"))
            except (OSError, ValueError):  # not written yet, or being replaced
                continue
            row = (time.monotonic(), s["state"], s["zenoh"]["routers"], s["zenoh"]["warning"],
                   s["frames"]["published"])
            if not self.rows or row[1:4] != self.rows[-1][1:4] or row[4] != self.rows[-1][4]:
                self.rows.append(row)

    def between(self, start: float, end: float) -> list[dict]:
        """The distinct (state, routers, warning) the status said in [start, end], with frames published."""
        seen: dict[tuple, dict] = {}
        for t, state, routers, warning, published in self.rows:
            if start <= t <= end:
                key = (state, routers, warning)
                entry = seen.setdefault(key, {"state": state, "routers": routers, "warning": warning,
                                              "first_s": round(t - start, 2), "published_from": published})
                entry["published_to"] = published
        return list(seen.values())


def measure(number: int, killed: float, ready: float, subscriber, watcher: Watcher, status_log: HealthLog,
            give_up_s: float) -> dict:
    """One cycle's figures, the router killed at ``killed`` and listening again at ``ready`` (monotonic s)."""
    sub_back = time.monotonic() if wait_until(lambda: list(subscriber.info.routers_zid()), give_up_s, 0.01) else None
    came = wait_until(lambda: any(t > ready for t in watcher.frame_times[-5:]), give_up_s, 0.005)
    first = next((t for t in watcher.frame_times if t > ready), None) if came else None
    last_before = max((t for t in watcher.frame_times if t < killed), default=killed)
    return {"cycle": number, "recovery_s": None if first is None else round(first - ready, 3),
            "subscriber_reconnected_s": None if sub_back is None else round(max(sub_back - ready, 0.0), 3),
            "gap_s": None if first is None else round(first - last_before, 3),
            "status_meanwhile": status_log.between(killed, first or time.monotonic())}


def parse(argv: list[str] | None) -> tuple[argparse.Namespace, list[str]]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--cycles", type=int, default=5)
    p.add_argument("--down-s", type=float, default=3.0, help="seconds the router stays dead")
    p.add_argument("--give-up-s", type=float, default=30.0, help="a cycle fails when no frame came by then")
    p.add_argument("--work", type=Path, default=Path("/tmp/swarmpose-router-restart"))
    p.add_argument("--zenoh-config", default="", help="a zenoh JSON5 file for the daemon and the subscriber")
    p.add_argument("--as-router", type=int, default=0, help=argparse.SUPPRESS)
    args, more = p.parse_known_args(argv)
    return args, [m for m in more if m != "--"]


def main(argv: list[str] | None = None) -> int:
    args, more = parse(argv)
    if args.as_router:
        run_router(args.as_router)
        return 0
    args.work.mkdir(parents=True, exist_ok=True)
    seq = synth_folder(args.work / "seq")
    health = args.work / "status.json"
    health.unlink(missing_ok=True)
    port = free_local_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router, _ = start_router(port)
    flags = ["--zenoh-mode", "client", "--connect", endpoint, "--no-multicast", "--health-file", str(health),
             "--status-period-s", "0.2", "--particles", "8", "--generations", "4", "--tile", "16x16",
             "--max-people", "1", *(["--zenoh-config", args.zenoh_config] if args.zenoh_config else []), *more]
    daemon = serve(seq, CAMERA, args.work / "serve.log", *flags)
    subscriber = open_session(zenoh_config("client", [endpoint], multicast=False, config_file=args.zenoh_config),
                              "subscriber")
    watcher = Watcher(CAMERA)
    subs = watcher.attach(subscriber, keep_times=True)
    status_log = HealthLog(health)
    status_log.start()
    cycles = []
    try:
        if not wait_until(lambda: watcher.frames >= 20, 120.0, 0.1):
            raise RuntimeError(f"no frames from the daemon (see {args.work / 'serve.log'})")
        for k in range(args.cycles):
            router.kill()
            killed = time.monotonic()
            router.wait()
            time.sleep(args.down_s)
            router, ready = start_router(port)
            cycle = measure(k + 1, killed, ready, subscriber, watcher, status_log, args.give_up_s)
            cycles.append(cycle)
            print(f"cycle {k + 1}: frames again {cycle['recovery_s']} s after the restart (subscriber "
                  f"reconnected {cycle['subscriber_reconnected_s']} s); status: "
                  + "; ".join(f"{s['state']}/routers={s['routers']}/{s['warning'] or 'no warning'}"
                              for s in cycle["status_meanwhile"]), flush=True)
            wait_until(lambda: watcher.frames > 0 and watcher.frame_times[-1] > time.monotonic() - 0.5, 10.0, 0.1)
            time.sleep(2.0)                        # frames flow a while before the next kill
    finally:
        exit_status = stop(daemon)
        status_log.done.set()
        router.kill()
        router.wait()
        del subs
        subscriber.close()
    times = [c["recovery_s"] for c in cycles if c["recovery_s"] is not None]
    report = {"cycles": cycles, "down_s": args.down_s, "serve_flags": flags, "zenoh_config": args.zenoh_config,
              "recovery_median_s": statistics.median(times) if times else None,
              "recovery_max_s": max(times) if times else None, "goal_s": GOAL_S,
              "all_recovered": len(times) == len(cycles), "daemon_exit_status": exit_status}
    (args.work / "report.json").write_text(json.dumps(report, indent=1))
    print(json.dumps({k: v for k, v in report.items() if k != "cycles"}))
    return 0 if report["all_recovered"] else 1


if __name__ == "__main__":
    sys.exit(main())
