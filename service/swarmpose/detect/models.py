"""The 2D networks swarmpose can run by name: where it looks for them, what it finds there, and
installing a downloaded one into the user's models folder (``swarmpose models``)."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from swarmpose.core.errors import DetectorError
from swarmpose.detect.registry import NETWORKS, model_folders, user_models_folder

LICENCES = {"movenet": "Apache-2.0 (Google, MoveNet single-pose lightning)",
            "blazepose": "Apache-2.0 (Google, MediaPipe BlazePose full landmark)"}
"""What each named network is and its licence, as the README's '2D joints' says where to get it."""


@dataclass(frozen=True)
class FoundModel:
    """One network file in a models folder: its name (``--detector NAME``), path, size (bytes),
    keypoint layout and licence note; ``used``: the first found of its name (what runs)."""

    name: str
    path: Path
    size: int
    layout: str
    licence: str
    used: bool


def layout_of(path: Path, adapter: str | None = None) -> tuple[str, str]:
    """(network name, keypoint layout name) of the ONNX file ``path``, checked by loading it with
    onnxruntime and matching its inputs and outputs to a known network (``adapter``: that one only).
    DetectorError naming the file when it cannot be loaded or matches none."""
    from swarmpose.detect.onnx_pose import OnnxPoseDetector

    detector = OnnxPoseDetector(path, adapter=adapter, threads=1)
    try:
        return detector.adapter.name, detector.layout.name
    finally:
        detector.close()


def found_models(models: str = "") -> tuple[list[Path], list[FoundModel]]:
    """(the folders searched, in order; the named networks found in them, each loaded and checked)."""
    folders = model_folders(models)
    found: list[FoundModel] = []
    for folder in folders:
        for name, filename in NETWORKS.items():
            path = folder / filename
            if not path.is_file():
                continue
            try:
                _, layout = layout_of(path, name)
            except DetectorError as exc:
                layout = f"unusable: {exc}"
            used = not any(m.name == name for m in found)
            found.append(FoundModel(name, path, path.stat().st_size, layout, LICENCES[name], used))
    return folders, found


def add_model(file: str | Path, force: bool = False) -> tuple[str, Path]:
    """Install the ONNX network ``file`` into the user's models folder under the file name its
    network is looked up by: (network name, installed path). DetectorError when onnxruntime
    cannot load it, its inputs and outputs match no known network, or (without ``force``) a
    different file of that name is installed already."""
    source = Path(file).expanduser()
    if not source.is_file():
        raise DetectorError(f"{source}: no such file; download the network first (README, '2D joints')")
    name, _ = layout_of(source)
    target = user_models_folder() / NETWORKS[name]
    if target.exists() and not force and target.read_bytes() != source.read_bytes():
        raise DetectorError(f"{target} holds another {name} network; pass --force to replace it")
    target.parent.mkdir(parents=True, exist_ok=True)
    if source.resolve() != target.resolve():
        shutil.copyfile(source, target)
    return name, target
