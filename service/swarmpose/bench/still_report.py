"""The tables of ``swarmpose bench still`` (:mod:`swarmpose.bench.still`), in Markdown."""

from __future__ import annotations


def _mm(value: float | None, digits: int = 1) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def format_summary(groups: list[dict]) -> str:
    """One line per (detector, smoothing) of :func:`~swarmpose.bench.still.summary`."""
    lines = ["| detector | smoothing | jitter mm (mean) | jitter mm (max, joint) | still Δ mm | lag ms | "
             "onset Δ mm | moving Δ mm |", "|---|---|---|---|---|---|---|---|"]
    for g in groups:
        lines.append(f"| {g['detector']} | {g['smoothing']} | {_mm(g['jitter_mm'])} | {_mm(g['jitter_max_mm'])} "
                     f"({g['jitter_worst'] or '–'}) | {_mm(g['still_delta_mm'])} | {_mm(g['lag_ms'], 0)} | "
                     f"{_mm(g['onset_delta_mm'])} | {_mm(g['moving_delta_mm'])} |")
    return "\n".join(lines)


def format_rows(rows: list[dict]) -> str:
    """One line per (sequence, detector, smoothing) row of :func:`~swarmpose.bench.still.run_still`."""
    lines = ["| sequence | detector | smoothing | jitter mm (mean / max, joint) | still Δ mm | lag ms | onset Δ mm | "
             "moving Δ mm |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['sequence']} | {r['detector']} | {r['smoothing']} | {_mm(r['jitter_mm'])} / "
                     f"{_mm(r['jitter_max_mm'])} ({r['jitter_worst'] or '–'}) | {_mm(r['still_delta_mm'])} | "
                     f"{_mm(r['lag_ms'], 0)} | {_mm(r['onset_delta_mm'])} | {_mm(r['moving_delta_mm'])} |")
    return "\n".join(lines)
