"""A numpy reader for BVH motion-capture files.

A BVH file has a ``HIERARCHY`` section (joints, their rest offsets from the parent and
the channels each one animates) and a ``MOTION`` section (``Frames:``, ``Frame Time:``
and one line of channel values per frame). This module reads it into a
:class:`BvhClip` of plain arrays: units are whatever the file uses (centimetres,
inches, decimetres ...) and the up axis is the file's own; retargeting deals with both.

Conventions: a joint's rotation is the product of its elementary rotations in the order
its channels list them, ``R = R_first @ R_second @ R_third`` (intrinsic), angles in
degrees in the file and rotation matrices acting on column vectors here. Forward
kinematics is the standard one: ``G_j = G_parent @ R_j`` and
``p_j = p_parent + G_parent @ offset_j``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmpose.body.kinematics import matrix_to_quaternion, quaternion_to_matrix
from swarmpose.core.errors import MotionError
from swarmpose.motion.bvh_positions import local_translations

_AXES = {"x": 0, "y": 1, "z": 2}
_FRAMES = re.compile(r"^frames\s*:\s*(\S+)\s*$", re.IGNORECASE)
_FRAME_TIME = re.compile(r"^frame\s+time\s*:\s*(\S+)\s*$", re.IGNORECASE)


@dataclass(frozen=True, eq=False)
class BvhClip:
    """One BVH clip: a joint hierarchy and its per-frame local transforms.

    ``J`` joints (End Sites excluded) in file order, which is topological; ``N`` frames.

    name: label (the file stem). joint_names: J names. parents: (J,) int, -1 for the root
    (index 0). offsets: (J, 3) rest offsets from the parent, file units (the root's is its
    OFFSET line). end_offsets: joint index -> (3,) End Site offset, file units.
    frame_time: seconds per frame. root_positions: (N, 3) root translation per frame,
    file units (the position channels, or the root offset where it has none).
    local_rotations: (N, J, 3, 3) rotation of each joint relative to its parent.
    local_translations: (N, J, 3) per-frame offsets for files whose non-root joints carry
    position channels (row 0 = root_positions; joints without channels keep their
    offset; channels holding positions in the root's frame are turned into offsets, see
    :mod:`swarmpose.motion.bvh_positions`), else None.
    """

    name: str
    joint_names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    end_offsets: dict[int, np.ndarray]
    frame_time: float
    root_positions: np.ndarray
    local_rotations: np.ndarray
    local_translations: np.ndarray | None = field(default=None)

    def __len__(self) -> int:
        return len(self.root_positions)

    @property
    def fps(self) -> float:
        """Frames per second, ``1 / frame_time``."""
        return 1.0 / self.frame_time

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame, ``(N - 1) * frame_time``."""
        return (len(self) - 1) * self.frame_time

    def joint_index(self, name: str) -> int:
        """Index of the joint called ``name`` (exact match); MotionError if there is none."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise MotionError(f"{self.name}: no joint named {name!r}; it has "
                              f"{', '.join(self.joint_names)}") from None

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: global rotations (N, J, 3, 3) and joint positions (N, J, 3), file units."""
        n, j = self.local_rotations.shape[:2]
        rot = np.empty((n, j, 3, 3))
        pos = np.empty((n, j, 3))
        rot[:, 0] = self.local_rotations[:, 0]
        pos[:, 0] = self.root_positions
        for k in range(1, j):
            par = int(self.parents[k])
            offset = self.offsets[k] if self.local_translations is None else self.local_translations[:, k]
            pos[:, k] = pos[:, par] + np.einsum("nij,nj->ni", rot[:, par], np.broadcast_to(offset, (n, 3)))
            rot[:, k] = rot[:, par] @ self.local_rotations[:, k]
        return rot, pos

    def rest_positions(self) -> np.ndarray:
        """Joint positions (J, 3) with every rotation zero: accumulated offsets, root at the origin."""
        pos = np.zeros((len(self.joint_names), 3))
        for k in range(1, len(self.joint_names)):
            pos[k] = pos[int(self.parents[k])] + self.offsets[k]
        return pos

    def resample(self, fps: float) -> BvhClip:
        """This clip sampled at times ``k / fps`` for ``0 <= k / fps <= duration``.

        Root positions (and local translations) are interpolated linearly, local
        rotations spherically (quaternion slerp, shortest arc). The result's frame time
        is ``1 / fps``.
        """
        if not (fps > 0 and np.isfinite(fps)):
            raise MotionError(f"{self.name}: cannot resample to {fps} fps; give a positive frame rate")
        n = len(self)
        count = int(np.floor(self.duration * fps + 1e-6)) + 1
        t = np.arange(count) / fps / self.frame_time  # in source frames
        lo = np.clip(np.floor(t).astype(np.int64), 0, max(n - 2, 0))
        hi = np.minimum(lo + 1, n - 1)
        w = np.clip(t - lo, 0.0, 1.0)

        def lerp(a: np.ndarray) -> np.ndarray:
            ww = w.reshape((-1,) + (1,) * (a.ndim - 1))
            return (1 - ww) * a[lo] + ww * a[hi]

        quats = matrix_to_quaternion(self.local_rotations)  # (N, J, 4)
        rotations = quaternion_to_matrix(slerp(quats[lo], quats[hi], w[:, None]))
        translations = None if self.local_translations is None else lerp(self.local_translations)
        return BvhClip(self.name, self.joint_names, self.parents, self.offsets, self.end_offsets,
                       1.0 / fps, lerp(self.root_positions), rotations, translations)


def slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit quaternions (..., 4) wxyz with weights ``w`` (...) in [0, 1].

    Takes the shorter arc (``q1`` is negated when ``q0 . q1 < 0``); nearly equal
    quaternions fall back to normalised linear interpolation.
    """
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-8
    safe = np.where(small, 1.0, sin)
    a = np.where(small, 1 - w, np.sin((1 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    out = a * q0 + b * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def euler_matrices(angles_deg: np.ndarray, axes: str) -> np.ndarray:
    """Intrinsic rotations ``R_axes[0](a0) @ R_axes[1](a1) ...``: angles (N, K) deg -> (N, 3, 3).

    ``axes`` names the K axes in order, e.g. ``"zxy"``.
    """
    angles = np.radians(np.asarray(angles_deg, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), (len(angles), 3, 3))
    for k, axis in enumerate(axes):
        out = out @ _elementary(_AXES[axis], angles[:, k])
    return np.array(out)


def _elementary(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotations (N, 3, 3) by ``angle`` (N,) rad about coordinate axis 0, 1 or 2."""
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros((len(angle), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[:, axis, axis] = 1.0
    m[:, i, i] = c
    m[:, j, j] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    return m


# ---------------------------------------------------------------------------- parsing
@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray | None = None
    channels: tuple[str, ...] = ()


class _Tokens:
    """The hierarchy's whitespace-separated tokens with their 1-based line numbers."""

    def __init__(self, path: Path, lines: list[str]) -> None:
        self.path = path
        self.items = [(tok, no) for no, line in enumerate(lines, 1) for tok in line.split()]
        self.pos = 0
        self.last_line = len(lines)

    def error(self, message: str, line: int | None = None) -> MotionError:
        where = f"{self.path}" if line is None else f"{self.path}, line {line}"
        return MotionError(f"{where}: {message}; fix the file or export it again as BVH")

    def peek(self) -> tuple[str, int]:
        if self.pos >= len(self.items):
            raise self.error("the HIERARCHY section ends early (no MOTION section?)", self.last_line)
        return self.items[self.pos]

    def take(self) -> tuple[str, int]:
        item = self.peek()
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        tok, line = self.take()
        if tok != word:
            raise self.error(f"expected {word!r} but found {tok!r}", line)
        return line

    def rest_of_line(self, line: int) -> str:
        """The remaining tokens on ``line`` (a joint name may hold spaces), a trailing '{' left in place."""
        words = []
        while self.pos < len(self.items) and self.items[self.pos][1] == line and self.items[self.pos][0] != "{":
            words.append(self.items[self.pos][0])
            self.pos += 1
        return " ".join(words)

    def numbers(self, count: int, what: str) -> np.ndarray:
        values = []
        for _ in range(count):
            tok, line = self.take()
            try:
                values.append(float(tok))
            except ValueError:
                raise self.error(f"{what} needs {count} numbers but has {tok!r}", line) from None
        return np.asarray(values)


def _parse_joint(tokens: _Tokens, joints: list[_Joint], ends: dict[int, np.ndarray], name: str, parent: int) -> None:
    """Parse a ``{ OFFSET .. CHANNELS .. children }`` block after ROOT/JOINT ``name``."""
    index = len(joints)
    joint = _Joint(name, parent)
    joints.append(joint)
    open_line = tokens.expect("{")
    while True:
        tok, line = tokens.take()
        word = tok.upper()
        if word == "OFFSET":
            joint.offset = tokens.numbers(3, f"the OFFSET of {name}")
        elif word == "CHANNELS":
            count_tok, _ = tokens.take()
            if not count_tok.isdigit():
                raise tokens.error(f"CHANNELS of {name} must start with a count, not {count_tok!r}", line)
            channels = tuple(tokens.take()[0] for _ in range(int(count_tok)))
            for ch in channels:
                if not re.fullmatch(r"[XYZ](position|rotation)", ch, re.IGNORECASE):
                    raise tokens.error(f"unknown channel {ch!r} of {name}", line)
            joint.channels = channels
        elif word == "JOINT":
            child = tokens.rest_of_line(line)
            if not child:
                raise tokens.error("JOINT without a name", line)
            _parse_joint(tokens, joints, ends, child, index)
        elif word == "END":
            tokens.rest_of_line(line)  # "Site"
            tokens.expect("{")
            tokens.expect("OFFSET")
            ends.setdefault(index, tokens.numbers(3, f"the End Site OFFSET of {name}"))
            tokens.expect("}")
        elif tok == "}":
            break
        else:
            raise tokens.error(f"unexpected {tok!r} inside joint {name}", line)
    if joint.offset is None:
        raise tokens.error(f"joint {name} has no OFFSET", open_line)


def _read_lines(path: Path) -> list[str]:
    if not path.exists():
        raise MotionError(f"{path}: no such BVH file; check the path")
    if not path.is_file():
        raise MotionError(f"{path}: is not a file; pass the path of a .bvh file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MotionError(f"{path}: cannot be read ({exc.strerror}); check its permissions") from None
    if b"\x00" in data:
        raise MotionError(f"{path}: is a binary file, not a BVH text file; pass a .bvh motion-capture file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return text.splitlines()


def _motion_error(path: Path, line: int, message: str) -> MotionError:
    return MotionError(f"{path}, line {line}: {message}; fix the file or export it again as BVH")


def read_bvh(path: str | Path) -> BvhClip:
    """Read the BVH file at ``path`` into a :class:`BvhClip`.

    Raises :class:`~swarmpose.core.errors.MotionError` (naming the file and line) when the file
    is missing, is not a BVH file, or has a malformed hierarchy or motion section.
    """
    path = Path(path)
    lines = _read_lines(path)
    first = next((line.split()[0] for line in lines if line.strip()), None)
    if first is None or first.upper() != "HIERARCHY":
        raise MotionError(f"{path}: does not start with HIERARCHY, so it is not a BVH file; "
                          "pass a .bvh motion-capture file")
    motion_at = next((k for k, line in enumerate(lines) if line.strip().upper() == "MOTION"), None)
    if motion_at is None:
        raise MotionError(f"{path}: has no MOTION section (truncated?); fix the file or export it again as BVH")

    tokens = _Tokens(path, lines[:motion_at])
    tokens.take()  # HIERARCHY, checked above
    joints: list[_Joint] = []
    ends: dict[int, np.ndarray] = {}
    tok, line = tokens.take()
    if tok.upper() != "ROOT":
        raise tokens.error(f"expected ROOT but found {tok!r}", line)
    _parse_joint(tokens, joints, ends, tokens.rest_of_line(line), -1)
    if tokens.pos < len(tokens.items):
        tok, line = tokens.items[tokens.pos]
        raise tokens.error(f"unexpected {tok!r} after the root joint (only one ROOT is supported)", line)

    frames, frame_time, rows = _read_motion(path, lines, motion_at)
    width = sum(len(j.channels) for j in joints)
    values = _parse_values(path, rows, width)
    return _build_clip(path, joints, ends, frame_time, values, frames)


def _read_motion(path: Path, lines: list[str], motion_at: int) -> tuple[int, float, list[tuple[int, str]]]:
    """``Frames:``, ``Frame Time:`` and the non-empty data lines as (line number, text)."""
    header = [(k + 1, lines[k].strip()) for k in range(motion_at + 1, len(lines)) if lines[k].strip()][:2]
    if len(header) < 2:
        raise _motion_error(path, len(lines), "the MOTION section lacks its Frames: and Frame Time: lines")
    (frames_no, frames_line), (time_no, time_line) = header
    m = _FRAMES.match(frames_line)
    if not m or not m.group(1).isdigit():
        raise _motion_error(path, frames_no, f"expected 'Frames: <count>' but found {frames_line[:60]!r}")
    frames = int(m.group(1))
    if frames < 1:
        raise _motion_error(path, frames_no, "the clip declares no frames")
    m = _FRAME_TIME.match(time_line)
    try:
        frame_time = float(m.group(1)) if m else float("nan")
    except ValueError:
        frame_time = float("nan")
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise _motion_error(path, time_no, f"expected 'Frame Time: <positive seconds>' but found {time_line[:60]!r}")
    rows = [(k + 1, lines[k]) for k in range(time_no, len(lines)) if lines[k].strip()]
    if len(rows) < frames:
        raise MotionError(f"{path}: is truncated: it declares Frames: {frames} but has {len(rows)} data lines; "
                          "export the clip again or correct the Frames: count")
    if len(rows) > frames:
        raise _motion_error(path, rows[frames][0], f"data continues past the declared Frames: {frames} "
                            f"({len(rows)} data lines); correct the Frames: count")
    return frames, frame_time, rows


def _parse_values(path: Path, rows: list[tuple[int, str]], width: int) -> np.ndarray:
    """The (N, width) channel values of the data lines; errors name the offending line."""
    split = [line.split() for _, line in rows]
    for (no, _), words in zip(rows, split, strict=True):
        if len(words) != width:
            raise _motion_error(path, no, f"has {len(words)} values but the hierarchy declares {width} channels")
    try:
        values = np.array(split, dtype=np.float64)
    except ValueError:
        for (no, _), words in zip(rows, split, strict=True):
            for word in words:
                try:
                    float(word)
                except ValueError:
                    raise _motion_error(path, no, f"{word[:30]!r} is not a number") from None
        raise
    finite = np.isfinite(values).all(axis=1)
    if not finite.all():
        no = rows[int(np.flatnonzero(~finite)[0])][0]
        raise _motion_error(path, no, "holds a NaN or infinite value")
    return values


def _build_clip(path: Path, joints: list[_Joint], ends: dict[int, np.ndarray], frame_time: float,
                values: np.ndarray, frames: int) -> BvhClip:
    n, count = frames, len(joints)
    offsets = np.stack([j.offset for j in joints])
    rotations = np.empty((n, count, 3, 3))
    translations = np.broadcast_to(offsets, (n, count, 3)).copy()
    positioned = np.zeros(count, dtype=bool)
    column = 0
    for k, joint in enumerate(joints):
        cols = np.arange(column, column + len(joint.channels))
        column += len(joint.channels)
        rot_cols = [c for c, ch in zip(cols, joint.channels, strict=True) if ch.lower().endswith("rotation")]
        axes = "".join(ch[0].lower() for ch in joint.channels if ch.lower().endswith("rotation"))
        rotations[:, k] = euler_matrices(values[:, rot_cols], axes)
        for c, ch in zip(cols, joint.channels, strict=True):
            if ch.lower().endswith("position"):
                translations[:, k, _AXES[ch[0].lower()]] = values[:, c]
                positioned[k] = True
    moved = bool(positioned[1:].any())
    if moved:  # a joint's channels may hold its position in the root's frame, not an offset
        translations = local_translations(np.array([j.parent for j in joints]), offsets, rotations, translations,
                                          positioned)
    return BvhClip(
        name=path.stem,
        joint_names=tuple(j.name for j in joints),
        parents=np.array([j.parent for j in joints], dtype=np.int64),
        offsets=offsets,
        end_offsets=ends,
        frame_time=float(frame_time),
        root_positions=translations[:, 0].copy(),
        local_rotations=rotations,
        local_translations=translations if moved else None,
    )
