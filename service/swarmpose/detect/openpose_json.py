"""2D joints read from OpenPose ``--write_json`` output (``openpose-json:DIR``).

OpenPose writes one file per frame, ``<name>_000000000000_keypoints.json``, holding
``{"people": [{"pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...]}, ...]}`` (pixels,
confidence 0..1, a missing keypoint is ``0, 0, 0``). The layout follows the keypoint count:
25 -> ``body25`` (BODY_25 model), 18 -> ``openpose18`` (OpenPose's COCO model).

Frame ``i`` reads the file whose 12-digit number is ``i`` when every file name carries
one (``..._000000000007_keypoints.json``), else the ``i``-th file in sorted order.
Several people -> the one with the highest mean confidence, or, when ``box`` is given, the
one whose confident keypoints' centre is closest to the box centre. No file for a frame,
or an empty ``people`` list -> every keypoint missing (score 0). A malformed file raises
:class:`~swarmpose.core.errors.DetectorError` naming it.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from swarmpose.body.skeleton import BODY25, OPENPOSE18, KeypointLayout
from swarmpose.core.errors import DetectorError
from swarmpose.detect.joints import Joints2D

LAYOUT_BY_COUNT: dict[int, KeypointLayout] = {25: BODY25, 18: OPENPOSE18}
_NUMBERED = re.compile(r"_(\d+)_keypoints\.json$")


def parse_people(path: Path) -> list[np.ndarray]:
    """The people of one OpenPose JSON file: a list of (K, 3) arrays (x px, y px, confidence).

    Raises DetectorError naming ``path`` when it is not OpenPose JSON or a person's
    keypoint count is not 25 or 18.
    """
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        people = data["people"]
        if not isinstance(people, list):
            raise TypeError("'people' is not a list")
        out = []
        for n, person in enumerate(people):
            flat = person.get("pose_keypoints_2d", person.get("pose_keypoints"))
            if flat is None:
                raise KeyError(f"people[{n}] has no 'pose_keypoints_2d'")
            arr = np.asarray(flat, dtype=np.float64)
            if arr.ndim != 1 or arr.size % 3 or arr.size // 3 not in LAYOUT_BY_COUNT:
                raise ValueError(f"people[{n}].pose_keypoints_2d has {arr.size} values; expected 75 (BODY_25) "
                                 "or 54 (COCO-18)")
            out.append(arr.reshape(-1, 3))
        return out
    except (OSError, UnicodeDecodeError) as exc:
        raise DetectorError(f"cannot read OpenPose JSON {path}: {exc}") from exc
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise DetectorError(f"{path} is not OpenPose --write_json output ({exc})") from exc


def pick_person(people: list[np.ndarray], box: np.ndarray | None = None) -> np.ndarray | None:
    """The person (K, 3) to report: closest to ``box``'s centre when given, else the highest mean confidence."""
    if not people:
        return None
    if box is not None:
        centre = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])

        def distance(kp: np.ndarray) -> float:
            ok = kp[:, 2] > 0
            return float(np.linalg.norm(kp[ok, :2].mean(axis=0) - centre)) if ok.any() else np.inf

        return min(people, key=distance)
    return max(people, key=lambda kp: float(kp[:, 2].mean()))


class OpenPoseJsonDetector:
    """Replays OpenPose JSON files as a detector; see the module doc for the file and person rules.

    folder: the ``--write_json`` folder; layout: ``"body25"`` or ``"openpose18"`` to force one
    (None: from the first file with a person; ``body25`` when no file has one).
    """

    def __init__(self, folder: str | Path, layout: str | None = None):
        self.folder = Path(folder).expanduser()
        if not self.folder.is_dir():
            raise DetectorError(f"OpenPose JSON folder {self.folder} not found; pass openpose-json:DIR "
                                "(the folder OpenPose --write_json wrote)")
        files = sorted(self.folder.glob("*_keypoints.json"))
        if not files:
            raise DetectorError(f"{self.folder} holds no OpenPose *_keypoints.json files")
        numbers = [_NUMBERED.search(f.name) for f in files]
        if all(numbers):
            self.files = {int(m.group(1)): f for m, f in zip(numbers, files)}
        else:
            self.files = dict(enumerate(files))
        self.name = f"openpose-json:{self.folder}"
        by_name = {lay.name: lay for lay in LAYOUT_BY_COUNT.values()}
        if layout is not None:
            if layout not in by_name:
                raise DetectorError(f"OpenPose layout must be one of {sorted(by_name)}, got {layout!r}")
            self.layout = by_name[layout]
        else:
            self.layout = self._first_layout()

    def _first_layout(self) -> KeypointLayout:
        """The layout of the first readable file with a person (unreadable files fail later, on their frame)."""
        for path in self.files.values():
            try:
                people = parse_people(path)
            except DetectorError:
                continue
            if people:
                return LAYOUT_BY_COUNT[len(people[0])]
        return BODY25

    def path_of(self, index: int) -> Path | None:
        """The JSON file of frame ``index``, None when there is none."""
        return self.files.get(int(index))

    def detect(self, frame, box: np.ndarray | None = None) -> Joints2D:
        """The keypoints recorded for ``frame.index`` (all missing when the frame has no file or no person)."""
        path = self.path_of(frame.index)
        keypoints = np.zeros((len(self.layout.keypoints), 3))
        if path is not None:
            person = pick_person(parse_people(path), None if box is None else np.asarray(box, float).reshape(4))
            if person is not None:
                if len(person) != len(keypoints):
                    raise DetectorError(f"{path}: a person has {len(person)} keypoints, but this folder's layout "
                                        f"{self.layout.name} has {len(keypoints)}")
                keypoints = person
        return Joints2D(self.layout, keypoints, int(frame.index), int(frame.timestamp_ns))

    def close(self) -> None:
        """Nothing to release (files are read per frame)."""
