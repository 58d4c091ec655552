"""``open_source(uri)``: the frame source a ``--source`` URI names.

Schemes (``scheme:argument``):

* ``folder:DIR`` — a ``swarmpose synth`` / Open3D ``color/`` + ``depth/`` folder or a TUM RGB-D
  folder (:mod:`.folder`). A bare path to an existing directory means the same.
* ``rgbd:COLOR.png,DEPTH.png,INTRINSICS.json`` — one still frame (:mod:`.still`).
* ``mkv:FILE.mkv`` — an Azure Kinect recording, read with PyAV, depth registered to colour
  with the recording's calibration (:mod:`.mkv`).
* ``bag:FILE.bag`` — a RealSense recording, through Open3D's ``RSBagReader`` (:mod:`.open3d_io`).
* ``realsense:`` — a live RealSense camera (first one, or ``realsense:SERIAL``, or
  ``realsense:CONFIG.json`` with an Open3D ``RealSenseSensorConfig``) (:mod:`.open3d_io`).
* ``azure:`` — a live Azure Kinect (``azure:INDEX``; ``azure:INDEX,INTRINSICS.json`` to give
  the colour intrinsics instead of reading the factory calibration) (:mod:`.open3d_io`).
* ``openni2:`` — the first OpenNI2 device; ``openni2:FILE.oni`` plays a recording;
  ``openni2:URI`` opens a device by its OpenNI URI (:mod:`.openni2`).
* ``utdmhad:FILE.mat[?lag=FRAMES]`` — a UTD-MHAD depth file (``aA_sS_tT_depth.mat``) with its
  Kinect skeleton as ground truth, in time with the depth (``lag``: the frames the depth trails
  the skeleton, 1.75 measured, 0 the files' pairing; :mod:`.utdmhad`).

A bare path to a ``.mkv``, ``.bag``, ``.oni`` or ``.mat`` file is read with that file's scheme.

Errors: an unknown scheme or a malformed argument raises :class:`~swarmpose.core.errors.ConfigError`
listing the schemes; a missing file, device or library raises
:class:`~swarmpose.core.errors.SourceError` naming it and what to do. After the first frame no
source raises: see :mod:`swarmpose.sources.base` for the failure policy (skipped frames,
``status``, bounded reconnects of live devices).

Imports inside the functions are deliberate: each source module is imported when its scheme
is used, so opening a folder never loads PyAV, Open3D's sensors or OpenNI2.
"""

from __future__ import annotations

from pathlib import Path

from swarmpose.core.errors import ConfigError, SourceError
from swarmpose.sources.base import FrameSource

SCHEMES = {
    "folder": "folder:DIR (swarmpose synth, Open3D color/+depth/ or TUM RGB-D folder)",
    "rgbd": "rgbd:COLOR.png,DEPTH.png,INTRINSICS.json (one frame)",
    "mkv": "mkv:FILE.mkv (Azure Kinect recording)",
    "bag": "bag:FILE.bag (RealSense recording)",
    "realsense": "realsense:[SERIAL|CONFIG.json] (live RealSense)",
    "azure": "azure:[INDEX][,INTRINSICS.json] (live Azure Kinect)",
    "openni2": "openni2:[FILE.oni|URI] (OpenNI2 device or recording)",
    "utdmhad": "utdmhad:aA_sS_tT_depth.mat[?lag=FRAMES] (UTD-MHAD depth with its Kinect skeleton)",
}
_BY_SUFFIX = {".mkv": "mkv", ".bag": "bag", ".oni": "openni2", ".mat": "utdmhad"}

_HINTS = {
    "mkv": "record one with the Azure Kinect's k4arecorder",
    "bag": "record one with the RealSense Viewer (realsense-viewer)",
    "openni2": "record one with OpenNI2's NiViewer or openni2.Recorder",
    "utdmhad": "pass PATH/aA_sS_tT_depth.mat of UTD-MHAD",
}


def _existing_file(path: str, scheme: str) -> Path:
    if not path:
        raise ConfigError(f"{scheme}: needs a file, e.g. {SCHEMES[scheme].split(' ')[0]}")
    p = Path(path).expanduser()
    if not p.is_file():
        raise SourceError(f"{scheme}: file {p} does not exist; check the path ({_HINTS[scheme]})")
    return p


def _split(uri: str) -> tuple[str, str]:
    text = uri.strip()
    if not text:
        raise ConfigError("--source is empty; choose one of: " + "; ".join(SCHEMES.values()))
    scheme, sep, rest = text.partition(":")
    if sep and scheme.lower() in SCHEMES:
        return scheme.lower(), rest
    path = Path(text).expanduser()
    if path.is_dir():
        return "folder", text
    if path.suffix.lower() in _BY_SUFFIX and (path.is_file() or not sep):
        return _BY_SUFFIX[path.suffix.lower()], text
    if sep and len(scheme) > 1:
        raise ConfigError(f"unknown source scheme {scheme!r} in {uri!r}; choose one of: " + "; ".join(SCHEMES.values()))
    raise SourceError(f"source {uri!r} is neither an existing folder nor a URI with a scheme; choose one of: "
                      + "; ".join(SCHEMES.values()))


def _utdmhad_options(arg: str) -> tuple[str, dict[str, float]]:
    """``FILE.mat[?lag=FRAMES]`` -> (FILE.mat, the source's keyword arguments)."""
    file, sep, query = arg.partition("?")
    if not sep:
        return file, {}
    key, _, value = query.partition("=")
    try:
        lag = float(value) if key == "lag" else None
    except ValueError:
        lag = None
    if lag is None:
        raise ConfigError(f"utdmhad: cannot read the option {query!r} of {file}; the one option is ?lag=FRAMES "
                          "(the frames the depth trails the skeleton; 0 keeps the files' pairing)")
    return file, {"lag_frames": lag}


def open_source(uri: str) -> FrameSource:
    """Open the frame source ``uri`` names (see the module docstring); the caller closes it."""
    scheme, arg = _split(uri)
    if scheme == "folder":
        from swarmpose.sources.folder import FolderSource
        if not arg:
            raise ConfigError("folder: needs a directory, e.g. folder:/tmp/seq")
        return FolderSource(arg, uri=uri)
    if scheme == "rgbd":
        from swarmpose.sources.still import StillSource
        return StillSource.from_spec(arg, uri=uri)
    if scheme == "mkv":
        path = _existing_file(arg, "mkv")
        from swarmpose.sources.mkv import MkvSource
        return MkvSource(path, uri=uri)
    if scheme == "bag":
        path = _existing_file(arg, "bag")
        from swarmpose.sources.open3d_io import BagSource
        return BagSource(path, uri=uri)
    if scheme == "realsense":
        from swarmpose.sources.open3d_io import RealSenseSource
        return RealSenseSource(arg, uri=uri)
    if scheme == "azure":
        from swarmpose.sources.open3d_io import AzureKinectSource
        return AzureKinectSource(arg, uri=uri)
    if scheme == "openni2":
        from swarmpose.sources.openni2 import OpenNI2Source
        if arg.lower().endswith(".oni"):
            return OpenNI2Source(file=_existing_file(arg, "openni2"), uri=uri)
        return OpenNI2Source(device_uri=arg or None, uri=uri)
    if scheme == "utdmhad":
        from swarmpose.sources.utdmhad import UtdMhadSource
        file, options = _utdmhad_options(arg)
        return UtdMhadSource(_existing_file(file, "utdmhad"), uri=uri, **options)
    raise AssertionError(scheme)  # pragma: no cover - _split only returns known schemes
