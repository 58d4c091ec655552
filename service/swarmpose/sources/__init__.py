"""Frame sources: where depth and colour frames come from (see :mod:`swarmpose.sources.base`)."""
