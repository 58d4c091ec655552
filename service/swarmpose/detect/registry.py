"""``--detector SPEC`` (older name ``--joints``) -> a 2D joint detector.

Forms:

* ``auto`` (the default): ``simulated`` where the source carries recorded detections (a
  ``swarmpose synth`` sequence, a UTD-MHAD file), else ``movenet``: a real network on a
  user's own camera or recording;
* ``movenet`` / ``blazepose`` (``NAME[?options]``): the network of that name, looked up by its
  file name (:data:`NETWORKS`) in the models folders (:func:`model_folders`: ``--models`` /
  ``$SWARMPOSE_MODELS``, then ``$XDG_DATA_HOME/swarmpose/models``, then the shared assets'
  ``pose2d``), with the ``onnx:`` form's options;
* ``simulated``: the detections ``swarmpose synth`` recorded (the source must be a synth
  sequence folder, whose ``ground_truth`` attribute holds them);
* ``onnx:MODEL[?adapter=movenet|blazepose&threads=N&margin=F&refine=BOOL]``: an ONNX pose network
  (MoveNet single-pose or BlazePose full landmark), see :mod:`.onnx_pose`;
* ``openpose-json:DIR[?layout=body25|openpose18]``: OpenPose ``--write_json`` files, see :mod:`.openpose_json`.

Imports inside the functions are deliberate: each detector module is imported when its spec
is used, so the simulated detector never loads onnxruntime.
"""

from __future__ import annotations

import os
from pathlib import Path
from urllib.parse import parse_qsl

from swarmpose.core.assets import asset_folders
from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import parse_bool
from swarmpose.detect.joints import Detector

FORMS = ("auto", "movenet", "blazepose", "simulated",
         "onnx:MODEL[?adapter=movenet|blazepose&threads=N&margin=F&refine=BOOL]",
         "openpose-json:DIR[?layout=body25|openpose18]")

NETWORKS = {"movenet": "movenet_singlepose_lightning.onnx", "blazepose": "blazepose_landmark_full.onnx"}
"""Network name -> the ONNX file it is looked up by in the models folders."""

ONNX_OPTIONS = {"adapter": str, "threads": int, "margin": float, "refine": parse_bool}
MODELS_HELP = ("put the .onnx file there or name a folder with --models DIR / SWARMPOSE_MODELS (README.md, "
               "'2D joints': where the files come from), or pass --detector onnx:PATH")


def model_folders(models: str = "") -> list[Path]:
    """Where ``--detector movenet|blazepose`` looks, in order: ``models`` (else ``$SWARMPOSE_MODELS``),
    ``$XDG_DATA_HOME/swarmpose/models`` (``~/.local/share/swarmpose/models``: :func:`user_models_folder`),
    then the shared assets' ``pose2d`` (:func:`~swarmpose.core.assets.asset_folders`: ``$SWARMPOSE_ASSETS``,
    ``../shared/assets`` from the working directory, beside the checkout), whatever the working directory."""
    first = models or os.environ.get("SWARMPOSE_MODELS", "")
    return [*([Path(first).expanduser()] if first else []), user_models_folder(),
            *(folder / "pose2d" for folder in asset_folders())]


def user_models_folder() -> Path:
    """The user's models folder: ``$XDG_DATA_HOME/swarmpose/models`` (``~/.local/share/swarmpose/models``)."""
    data = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return data / "swarmpose" / "models"


def find_network(name: str, models: str = "") -> Path:
    """The ONNX file of network ``name`` (a key of :data:`NETWORKS`) in the first of :func:`model_folders`
    that holds it; ConfigError naming every folder tried and the fix otherwise."""
    first = models or os.environ.get("SWARMPOSE_MODELS", "")
    if first and not Path(first).expanduser().is_dir():  # a misspelt folder must not fall through to others
        raise ConfigError(f"--models {first}: no such folder; name the folder that holds {NETWORKS[name]} "
                          "(in a container: mount it there)")
    folders = model_folders(models)
    for folder in folders:
        if (folder / NETWORKS[name]).is_file():
            return folder / NETWORKS[name]
    tried = ", ".join(str(f) for f in folders)
    raise ConfigError(f"--detector {name}: {NETWORKS[name]} is not in any models folder ({tried}); {MODELS_HELP}")


def has_recorded_detections(source) -> bool:
    """Whether ``auto`` replays ``source``'s recorded detections: a synthetic sequence's truth plus
    noise (the simulated detector). A source whose ground truth is a measurement to evaluate
    against (``replays_detections`` False: UTD-MHAD's Kinect skeleton) gets a network instead."""
    return getattr(source, "ground_truth", None) is not None and getattr(source, "replays_detections", True)


def _split_options(spec: str, rest: str, allowed: dict[str, type]) -> tuple[str, dict]:
    """``PATH?k=v&k=v`` -> (PATH, {k: typed v}); ConfigError for unknown keys or bad values."""
    path, _, query = rest.partition("?")
    if not path:
        raise ConfigError(f"--detector {spec!r} names no file or folder; use one of: {', '.join(FORMS)}")
    options = {}
    for key, value in parse_qsl(query, keep_blank_values=True):
        if key not in allowed:
            raise ConfigError(f"--detector {spec!r}: unknown option {key!r}; options are {sorted(allowed)}")
        try:
            options[key] = allowed[key](value)
        except ValueError:
            kinds = {int: "an integer", float: "a number", parse_bool: "a boolean (true/false)"}
            kind = kinds.get(allowed[key], "valid")
            raise ConfigError(f"--detector {spec!r}: option {key}={value!r} is not {kind}") from None
    return path, options


def resolve_detector(spec: str, source=None) -> str:
    """``spec`` with ``auto`` made concrete: ``simulated`` for a source whose recorded detections ``auto``
    replays (:func:`has_recorded_detections`), else ``movenet``."""
    spec = spec.strip()
    if spec != "auto":
        return spec
    return "simulated" if has_recorded_detections(source) else "movenet"


def detector_note(requested: str, detector: Detector) -> str:
    """What a run says about its 2D joints: the detector ``requested`` (``--detector``) became,
    with its model file, and, where ``auto`` picked the recorded detections, that it did."""
    path = getattr(detector, "path", None)
    text = f"2D joints: {getattr(detector, 'name', type(detector).__name__)}" + (f" ({path})" if path else "")
    if requested.strip() == "auto" and getattr(detector, "name", "") == "simulated":
        text += (": the detections the source recorded (--detector auto picks them on a synthetic sequence: "
                 "its own truth plus noise, not a network; pass --detector movenet to run one)")
    return text


def make_detector(spec: str, source=None, models: str = "") -> Detector:
    """The detector named by ``spec`` (see the module doc); ``source`` is the frame source (for ``simulated``
    and ``auto``); ``models``: the first folder to look for named networks in (see :func:`model_folders`).

    Raises ConfigError for a spec of none of the forms or a named network not found, DetectorError when
    the detector cannot be built (missing model, folder or ground truth).
    """
    spec = resolve_detector(spec, source)
    name, _, query = spec.partition("?")
    if name in NETWORKS:
        from swarmpose.detect.onnx_pose import OnnxPoseDetector

        path = find_network(name, models)
        _, opts = _split_options(spec, f"{path}?{query}", ONNX_OPTIONS)
        return OnnxPoseDetector(path, **{"adapter": name, **opts})
    if spec == "simulated":
        from swarmpose.detect.simulated import SimulatedDetector

        name = getattr(source, "uri", None) or ("no source" if source is None else type(source).__name__)
        return SimulatedDetector(getattr(source, "ground_truth", None), source_name=str(name))
    if spec.startswith("onnx:"):
        from swarmpose.detect.onnx_pose import OnnxPoseDetector

        path, opts = _split_options(spec, spec[5:], ONNX_OPTIONS)
        return OnnxPoseDetector(path, **opts)
    if spec.startswith("openpose-json:"):
        from swarmpose.detect.openpose_json import OpenPoseJsonDetector

        path, opts = _split_options(spec, spec[len("openpose-json:"):], {"layout": str})
        return OpenPoseJsonDetector(path, **opts)
    raise ConfigError(f"unknown --detector {spec!r}; use one of: {', '.join(FORMS)}")
