"""``folder:DIR``: RGBD image sequences on disk.

Two layouts are recognised:

* swarmpose / Open3D: ``color/`` (or ``rgb/``, ``image/``) and ``depth/`` holding files with
  the same stem (``000000.png``), depth uint16 millimetres (units per metre from
  ``intrinsic.json``'s ``depth_scale`` or ``sequence.json``'s ``depth_scale`` when given),
  ``intrinsic.json`` (required), and for ``swarmpose synth`` output ``sequence.json``
  (``fps``, ``frames``) and ``groundtruth.jsonl``. Frame ``i`` is file number ``i`` and is
  stamped ``i / fps`` (fps from ``sequence.json``, default 30).
* TUM RGB-D: ``rgb.txt`` and ``depth.txt`` (``timestamp path`` lines, ``#`` comments), depth
  PNGs with 5000 units per metre. Colour and depth are associated one-to-one by nearest
  timestamp within 20 ms (greedily, closest pairs first, as TUM's ``associate.py``); each
  frame carries the depth image's timestamp. Intrinsics from ``intrinsic.json`` when present,
  else the Freiburg defaults fx = fy = 525, cx = 319.5, cy = 239.5 (640x480 only).

A missing file (a colour image without depth or the reverse, a gap in the numbering up to
``sequence.json``'s ``frames``), an undecodable PNG, or a later frame whose depth and colour
differ in size is yielded as a :class:`~swarmpose.sources.base.SkippedFrame` whose reason
names the file, and iteration goes on. Depth and colour of different sizes in the *first*
complete frame, images of another size than the intrinsics, or a first depth image that
decodes but is not single-channel 16-bit (an 8-bit or colour export) raise
:class:`~swarmpose.core.errors.SourceError` when the folder is opened: that is a folder of
unregistered images or of pictures of the depth, not a damaged frame.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterator
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import AssetError, SourceError
from swarmpose.sources.base import DeferredFrame, Frame, FrameSource, SkippedFrame
from swarmpose.sources.groundtruth import GroundTruth, load_ground_truth
from swarmpose.sources.imagefiles import MILLIMETRES, check_pair, image_size, load_intrinsics, read_color, read_depth

COLOR_DIRS = ("color", "rgb", "image")
COLOR_SUFFIXES = (".png", ".jpg", ".jpeg")
DEFAULT_FPS = 30.0
TUM_UNITS_PER_METRE = 5000.0
TUM_MAX_DIFFERENCE_S = 0.02
TUM_FREIBURG = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)


@dataclass(frozen=True)
class _Entry:
    """One frame slot: its index, timestamp (ns), files (None = missing) or why it cannot be read."""

    index: int
    timestamp_ns: int
    color: Path | None
    depth: Path | None
    reason: str | None = None


class FolderSource(FrameSource):
    """Frames of an image folder (see the module docstring for the layouts).

    Attributes: ``folder`` (Path), ``layout`` ("sequence" or "tum"), ``length`` (frame slots,
    skipped ones included), ``fps`` (Hz: ``sequence.json``'s, or TUM's median depth rate),
    ``intrinsics``, ``ground_truth`` (:class:`~swarmpose.sources.groundtruth.GroundTruth` from
    ``groundtruth.jsonl``, None if absent), ``recorded_body`` (the name of the body
    ``swarmpose synth`` rendered, from ``sequence.json``; "" when not recorded). Can defer the
    reading of its images (:class:`~swarmpose.sources.base.DeferredFrame`).
    """

    can_defer = True

    def __init__(self, folder: Path | str, uri: str | None = None):
        self.folder = Path(folder).expanduser()
        self.uri = uri or f"folder:{self.folder}"
        if not self.folder.is_dir():
            raise SourceError(f"folder {self.folder} does not exist; give a sequence folder written by "
                              "`swarmpose synth`, an Open3D color/+depth/ folder or a TUM RGB-D folder")
        if (self.folder / "rgb.txt").is_file() and (self.folder / "depth.txt").is_file():
            self.layout = "tum"
            self.recorded_body = ""
            self._entries, self.fps = self._tum_entries()
            self._units = TUM_UNITS_PER_METRE
        else:
            self.layout = "sequence"
            self._entries, self.fps, self._units = self._sequence_entries()
        self.length = len(self._entries)
        self.intrinsics = self._intrinsics()
        self._check_first_frame()
        try:
            self.ground_truth: GroundTruth | None = load_ground_truth(self.folder)
        except AssetError as exc:
            raise SourceError(str(exc)) from exc

    # -- layouts -------------------------------------------------------------------------------

    def _sequence_entries(self) -> tuple[list[_Entry], float, float]:
        color_dir = next((self.folder / d for d in COLOR_DIRS if (self.folder / d).is_dir()), None)
        depth_dir = self.folder / "depth"
        if color_dir is None or not depth_dir.is_dir():
            raise SourceError(f"folder {self.folder} has no color/ and depth/ subfolders and no TUM rgb.txt + "
                              "depth.txt; it is not an RGBD sequence (write one with `swarmpose synth`)")
        meta = self._sequence_json()
        self.recorded_body = str(meta.get("body") or "")
        fps = float(meta.get("fps", DEFAULT_FPS))
        self.rate_known = "fps" in meta
        if not fps > 0:
            raise SourceError(f"{self.folder / 'sequence.json'}: fps must be positive, got {fps}")
        units = float(meta.get("depth_scale", MILLIMETRES))
        colors = {p.stem: p for p in sorted(color_dir.iterdir()) if p.suffix.lower() in COLOR_SUFFIXES}
        depths = {p.stem: p for p in sorted(depth_dir.iterdir()) if p.suffix.lower() == ".png"}
        stems = set(colors) | set(depths)
        if not stems:
            raise SourceError(f"folder {self.folder}: {color_dir.name}/ and depth/ hold no images (.png, .jpg); "
                              "write a sequence with `swarmpose synth` or copy the recording's images there")
        if all(s.isdigit() for s in stems):
            number = {s: int(s) for s in stems}
            width = max((len(s) for s in stems), default=6)
            present = set(number.values())
            for i in range(int(meta.get("frames", 0))):
                if i not in present:
                    number[f"{i:0{width}d}"] = i
        else:
            number = {s: i for i, s in enumerate(sorted(stems))}
        entries = []
        for stem, i in sorted(number.items(), key=lambda kv: kv[1]):
            c, d = colors.get(stem), depths.get(stem)
            reason = None
            if c is None and d is None:
                reason = (f"frame {i} is missing: neither {color_dir.name}/{stem}.png nor depth/{stem}.png exists "
                          f"(sequence.json promises {meta.get('frames')} frames)")
            elif c is None:
                reason = f"colour image {color_dir.name}/{stem}.* is missing for {d}"
            elif d is None:
                reason = f"depth image depth/{stem}.png is missing for {c}"
            entries.append(_Entry(i, int(round(i * 1e9 / fps)), c, d, reason))
        if not entries:
            raise SourceError(f"folder {self.folder}: {color_dir.name}/ and depth/ hold no images")
        return entries, fps, units

    def _sequence_json(self) -> dict:
        path = self.folder / "sequence.json"
        if not path.is_file():
            return {}
        try:
            meta = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise SourceError(f"{path} is not readable JSON: {exc}") from exc
        return meta if isinstance(meta, dict) else {}

    def _tum_list(self, name: str) -> list[tuple[int, Path]]:
        """(timestamp ns, exact from the decimal text; path) rows of rgb.txt / depth.txt, by time."""
        path = self.folder / name
        rows = []
        for lineno, line in enumerate(path.read_text().splitlines(), 1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            parts = line.split()
            try:
                rows.append((int(Decimal(parts[0]) * 1_000_000_000), self.folder / parts[1]))
            except (IndexError, ValueError, InvalidOperation) as exc:
                raise SourceError(f"{path}:{lineno}: expected 'timestamp path', got {line!r}") from exc
        return sorted(rows, key=lambda r: r[0])

    def _tum_entries(self) -> tuple[list[_Entry], float]:
        rgb, depth = self._tum_list("rgb.txt"), self._tum_list("depth.txt")
        if not depth:
            raise SourceError(f"{self.folder / 'depth.txt'} lists no depth images")
        rgb_t = np.array([t for t, _ in rgb], dtype=np.int64)
        window = int(TUM_MAX_DIFFERENCE_S * 1e9)
        candidates = []
        for i, (t, _) in enumerate(depth):
            k = int(np.searchsorted(rgb_t, t))
            for j in (k - 1, k):
                if 0 <= j < len(rgb) and abs(int(rgb_t[j]) - t) <= window:
                    candidates.append((abs(int(rgb_t[j]) - t), i, j))
        pair: dict[int, int] = {}
        used: set[int] = set()
        for _, i, j in sorted(candidates):
            if i not in pair and j not in used:
                pair[i] = j
                used.add(j)
        slots = []
        ms = int(TUM_MAX_DIFFERENCE_S * 1000)
        for i, (t, d) in enumerate(depth):
            if i in pair:
                slots.append((t, rgb[pair[i]][1], d, None))
            else:
                slots.append((t, None, d, f"no colour image within {ms} ms of {d.relative_to(self.folder)}"))
        for j, (t, c) in enumerate(rgb):
            if j not in used:
                slots.append((t, c, None, f"no depth image within {ms} ms of {c.relative_to(self.folder)}"))
        slots.sort(key=lambda s: s[0])
        entries = [_Entry(k, t, c, d, r) for k, (t, c, d, r) in enumerate(slots)]
        gaps = np.diff([t for t, _ in depth])
        fps = float(1e9 / np.median(gaps)) if len(gaps) and np.median(gaps) > 0 else DEFAULT_FPS
        return entries, fps

    # -- checks ------------------------------------------------------------------------------

    def _intrinsics(self) -> Intrinsics:
        path = self.folder / "intrinsic.json"
        if path.is_file():
            intr, units = load_intrinsics(path)
            if units is not None:
                self._units = units
            return intr
        if self.layout == "tum":
            return TUM_FREIBURG
        raise SourceError(f"folder {self.folder} has no intrinsic.json; write the camera's intrinsics there "
                          "(Open3D PinholeCameraIntrinsic JSON: width, height, intrinsic_matrix)")

    def _check_first_frame(self) -> None:
        first = next((e for e in self._entries if e.reason is None), None)
        if first is None:
            return
        csize, dsize = image_size(first.color), image_size(first.depth)
        if csize is None or dsize is None:
            return  # reported as a skipped frame when iterating
        if csize != dsize:
            raise SourceError(f"{self.folder}: depth {dsize[0]}x{dsize[1]} ({first.depth.name}) and colour "
                              f"{csize[0]}x{csize[1]} ({first.color.name}) differ in size; swarmpose needs depth "
                              "registered to colour (same size): register the depth images first")
        isize = (self.intrinsics.width, self.intrinsics.height)
        if dsize != isize:
            raise SourceError(f"{self.folder}: images are {dsize[0]}x{dsize[1]} but the intrinsics are for "
                              f"{isize[0]}x{isize[1]}; fix intrinsic.json")
        try:
            read_depth(first.depth, self._units)
        except SourceError as exc:  # it decodes (it has a size), so it is not a depth image
            raise SourceError(f"{self.folder}: the depth images are not depth: {exc}; convert them to 16-bit PNGs "
                              f"of {self._units:g} units per metre") from exc

    # -- frames ------------------------------------------------------------------------------

    def _frames(self) -> Iterator[Frame | SkippedFrame | DeferredFrame]:
        for e in self._entries:
            if e.reason is not None:
                yield SkippedFrame(e.index, e.timestamp_ns, e.reason)
            elif self.defer:
                yield DeferredFrame(e.index, e.timestamp_ns, functools.partial(self._read, e))
            else:
                yield self._read(e)

    def _read(self, e: _Entry) -> Frame | SkippedFrame:
        """The frame of entry ``e``, or why it cannot be read."""
        try:
            depth = read_depth(e.depth, self._units)
            color = read_color(e.color)
        except SourceError as exc:
            return SkippedFrame(e.index, e.timestamp_ns, str(exc))
        mismatch = check_pair(depth, color, f"frame {e.index} ({e.depth.name})", self.intrinsics)
        if mismatch is not None:
            return SkippedFrame(e.index, e.timestamp_ns, mismatch)
        return Frame(e.index, e.timestamp_ns, depth, color, self.intrinsics)
