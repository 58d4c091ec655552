"""Where the shared assets (``../shared/assets``: networks, bodies, motion capture, real frames) are
looked for, independently of the working directory."""

from __future__ import annotations

import os
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parents[3]
"""The repository this package runs from (``service/swarmpose/core/assets.py`` lies three folders in);
for an installed package, the folder above its site-packages, where nothing is found."""


def asset_folders() -> list[Path]:
    """The candidate shared assets folders, in order: ``$SWARMPOSE_ASSETS`` alone where it is set, else
    ``../shared/assets`` from the working directory and ``shared/assets`` beside the package's checkout
    (one of them where both are the same folder)."""
    if os.environ.get("SWARMPOSE_ASSETS"):
        return [Path(os.environ["SWARMPOSE_ASSETS"]).expanduser()]
    here, beside = Path.cwd().parent / "shared" / "assets", CHECKOUT.parent / "shared" / "assets"
    return [here] if here.resolve() == beside.resolve() else [here, beside]
