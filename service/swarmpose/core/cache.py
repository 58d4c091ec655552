"""The user's cache folder for what is slow to build and the same every run (the built-in body's
mesh), so that a second start is quick.

Where: ``$SWARMPOSE_CACHE_DIR``, else ``$XDG_CACHE_HOME/swarmpose``, else ``~/.cache/swarmpose``.
Entries are ``.npz`` files named by a key that covers everything they depend on (the inputs and
the source of the code that builds them), written atomically (a temporary file renamed into
place), so a change of code or a crash mid-write never serves a stale or broken entry. A cache
that cannot be read or written is skipped: the value is built as if there were none.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """The cache folder (see the module doc); not created here."""
    if os.environ.get("SWARMPOSE_CACHE_DIR"):
        return Path(os.environ["SWARMPOSE_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "swarmpose"


def cache_key(*parts: object, sources: tuple[Path, ...] = ()) -> str:
    """A hex key of ``parts`` (their ``repr``) and the bytes of the ``sources`` files."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(repr(part).encode())
    for path in sources:
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()[:32]


def cached_arrays(kind: str, key: str, build: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The arrays stored as ``kind/key.npz`` in the cache, or ``build()``'s, which are then stored."""
    path = cache_dir() / kind / f"{key}.npz"
    try:
        with np.load(path, allow_pickle=False) as stored:
            return {name: stored[name] for name in stored.files}
    except FileNotFoundError:
        pass
    except (OSError, ValueError, zipfile.BadZipFile) as exc:  # a broken entry: build it again
        log.debug("cache entry %s unreadable (%s); building it again", path, exc)
    arrays = build()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npz.tmp", delete=False) as tmp:
            np.savez(tmp, **arrays)
        os.replace(tmp.name, path)
    except OSError as exc:
        log.debug("cannot write the cache entry %s (%s); going on without it", path, exc)
    return arrays
