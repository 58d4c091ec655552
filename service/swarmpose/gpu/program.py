"""Loading the kernels of ``swarmpose.cl`` (the top-level ``cl/`` folder) and building them.

Sources are read with :mod:`importlib.resources`; ``#include "include/x.h"`` lines are
expanded here (relative to the ``cl`` package, once per file), so the build needs no ``-I``
path and the source text that is built and memoised covers the headers too. Compile-time
sizes are passed as ``-D NAME=value`` options. A failed build raises
:class:`KernelBuildError` with the file, the options, the device and the build log. Built
programs are memoised by their context (:meth:`swarmpose.gpu.context.ClContext.program`).
"""

from __future__ import annotations

import re
from importlib import resources

from swarmpose.gpu.errors import KernelBuildError

PACKAGE = "swarmpose.cl"
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$', re.MULTILINE)


def read_source(filename: str, _seen: frozenset = frozenset()) -> str:
    """The text of ``cl/<filename>`` with its quoted ``#include`` lines expanded (each file once)."""
    try:
        text = resources.files(PACKAGE).joinpath(filename).read_text(encoding="utf-8")
    except (FileNotFoundError, OSError) as exc:
        raise KernelBuildError(filename, (), "(not built)", f"cannot read kernel source: {exc}") from exc
    seen = _seen | {filename}

    def expand(match: re.Match) -> str:
        name = match.group(1)
        if name in seen:
            return f"/* {name}: already included */"
        return f"/* begin {name} */\n{read_source(name, seen)}\n/* end {name} */"

    return _INCLUDE.sub(expand, text)


def define_options(defines: dict[str, object]) -> tuple[str, ...]:
    """``{"TW": 64, "CULL": True}`` -> ``("-D", "TW=64", "-D", "CULL=1")`` in sorted order."""
    opts: list[str] = []
    for name in sorted(defines):
        value = defines[name]
        if isinstance(value, bool):
            value = int(value)
        elif isinstance(value, float):
            value = f"{value!r}f"
        opts += ["-D", f"{name}={value}"]
    return tuple(opts)


def compile_program(context, filename: str, options: tuple[str, ...]):
    """Build ``cl/<filename>`` with ``options`` for ``context`` (no memo: see ``ClContext.program``)."""
    import pyopencl as cl

    source = read_source(filename)
    device = ", ".join(d.name.strip() for d in context.devices)
    try:
        return cl.Program(context, source).build(options=list(options))
    except cl.Error as exc:
        raise KernelBuildError(filename, options, device, str(exc)) from exc
