"""A TOML file read for a setting (a config file, a BVH joint map), every failure an error of the
caller's kind that names the file and what to do."""

from __future__ import annotations

import sys
from pathlib import Path

from swarmpose.core.errors import SwarmposeError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


def read_toml_file(path: str | Path, error: type[SwarmposeError], what: str, missing_fix: str,
                   invalid_fix: str = "") -> dict:
    """The top-level table of the TOML file ``path`` (``~`` expanded). Raises ``error`` with the text
    ``"{what} {path}: ..."``: for a missing file with ``missing_fix``, for one that cannot be read, and
    for one that is not valid TOML, with ``invalid_fix`` where given."""
    path = Path(path).expanduser()
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise error(f"{what} {path} does not exist; {missing_fix}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{what} {path} cannot be read: {exc}; pass a TOML text file") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{what} {path} is not valid TOML: {exc}" + (f"; {invalid_fix}" if invalid_fix else "")) from None


__all__ = ["read_toml_file"]
