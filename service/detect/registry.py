"""``--detector SPEC`` (older name ``--joints``) -> a 2D joint detector.

Forms:

* ``simulated``: the detections ``swarmpose synth`` recorded (the source must be a synth
  sequence folder, whose ``ground_truth`` attribute holds them);
* ``onnx:MODEL[?adapter=movenet|blazepose&threads=N&margin=F&refine=BOOL]``: an ONNX pose network
  (MoveNet single-pose or BlazePose full landmark), see :mod:`.onnx_pose`;
* ``openpose-json:DIR[?layout=body25|openpose18]``: OpenPose ``--write_json`` files, see :mod:`.openpose_json`.

Imports inside the functions are deliberate: each detector module is imported when its spec
is used, so the simulated detector never loads onnxruntime.
"""

from __future__ import annotations

from urllib.parse import parse_qsl

from swarmpose.core.errors import ConfigError
from swarmpose.core.settings import parse_bool
from swarmpose.detect.joints import Detector

FORMS = ("simulated", "onnx:MODEL[?adapter=movenet|blazepose&threads=N&margin=F&refine=BOOL]",
         "openpose-json:DIR[?layout=body25|openpose18]")


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


def make_detector(spec: str, source=None) -> Detector:
    """The detector named by ``spec`` (see the module doc); ``source`` is the frame source (for ``simulated``).

    Raises ConfigError for a spec of none of the forms, DetectorError when the detector
    cannot be built (missing model, folder or ground truth).
    """
    spec = spec.strip()
    if spec == "simulated":
        from swarmpose.detect.simulated import SimulatedDetector

        name = getattr(source, "uri", None) or ("no source" if source is None else type(source).__name__)
        return SimulatedDetector(getattr(source, "ground_truth", None), source_name=str(name))
    if spec.startswith("onnx:"):
        from swarmpose.detect.onnx_pose import OnnxPoseDetector

        path, opts = _split_options(spec, spec[5:], {"adapter": str, "threads": int, "margin": float,
                                                                  "refine": parse_bool})
        return OnnxPoseDetector(path, **opts)
    if spec.startswith("openpose-json:"):
        from swarmpose.detect.openpose_json import OpenPoseJsonDetector

        path, opts = _split_options(spec, spec[len("openpose-json:"):], {"layout": str})
        return OpenPoseJsonDetector(path, **opts)
    raise ConfigError(f"unknown --detector {spec!r}; use one of: {', '.join(FORMS)}")
