"""Messages as one human-readable line (for logs and the subscriber's output)."""

from __future__ import annotations


def format_status(message: dict) -> str:
    """One log line of a ``swarmpose.status`` message."""
    f, lat = message["frames"], message["latency_ms"]
    latency = "n/a" if lat["median"] is None else f"{lat['median']:.0f} ms (p95 {lat['p95']:.0f})"
    if message["state"] == "starting" and f["published"] == 0:
        waiting = (f"[{message['camera']}] starting: waiting for the first tracked frame (opening the source, "
                   f"compiling the OpenCL kernels, the first fit); {f['received']} frames read")
        if f["dropped"]:
            waiting += f", {f['dropped']} dropped meanwhile (only the newest frame waits)"
        return waiting + (f"; zenoh: {message['zenoh']['warning']}" if message["zenoh"]["warning"] else "")
    line = (f"[{message['camera']}] {message['state']}: {message['fps']:.2f} fps, latency {latency}, "
            f"frames {f['published']}/{f['received']} published (dropped {f['dropped']}, skipped {f['skipped']}, "
            f"failed {f['failed']}), source {message['source']['state']}, tracker {message['tracker']['state']}")
    if message["zenoh"]["warning"]:
        line += f"; zenoh: {message['zenoh']['warning']}"
    return line
