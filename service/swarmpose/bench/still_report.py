"""The tables of ``swarmpose bench still`` (:mod:`swarmpose.bench.still`), in Markdown."""

from __future__ import annotations

MEASURES = ("| jitter mm (mean) | jitter mm (max, joint) | still Δ mm | lag ms | onset Δ mm | moving Δ mm |",
            "---|---|---|---|---|---|")
"""The measure columns both tables end with: their header and its rule."""


def _mm(value: float | None, digits: int = 1) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _measures(r: dict) -> str:
    """A row's (or a group's) measure cells, :data:`MEASURES`' columns."""
    return (f"| {_mm(r['jitter_mm'])} | {_mm(r['jitter_max_mm'])} ({r['jitter_worst'] or '–'}) "
            f"| {_mm(r['still_delta_mm'])} | {_mm(r['lag_ms'], 0)} | {_mm(r['onset_delta_mm'])} "
            f"| {_mm(r['moving_delta_mm'])} |")


def format_summary(groups: list[dict]) -> str:
    """One line per (detector, smoothing) of :func:`~swarmpose.bench.still.summary`."""
    lines = ["| detector | smoothing " + MEASURES[0], "|---|---|" + MEASURES[1]]
    lines += [f"| {g['detector']} | {g['smoothing']} " + _measures(g) for g in groups]
    return "\n".join(lines)


def format_rows(rows: list[dict]) -> str:
    """One line per (sequence, detector, smoothing) row of :func:`~swarmpose.bench.still.run_still`."""
    lines = ["| sequence | detector | smoothing " + MEASURES[0], "|---|---|---|" + MEASURES[1]]
    lines += [f"| {r['sequence']} | {r['detector']} | {r['smoothing']} " + _measures(r) for r in rows]
    return "\n".join(lines)
