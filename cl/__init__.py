"""OpenCL kernel sources of swarmpose, shipped as package data (read by :mod:`swarmpose.gpu.program`).

This file makes ``swarmpose.cl`` a regular package, so :mod:`importlib.resources` finds the
kernels in editable installs (setuptools' editable finder does not resolve the mapped
namespace package) as well as in wheels.
"""
