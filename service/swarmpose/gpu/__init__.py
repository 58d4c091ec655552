"""OpenCL side of swarmpose: device choice, kernel building and the particle scorer.

``pyopencl`` is imported lazily by the modules that need it, so ``import swarmpose.gpu``
stays cheap. See :mod:`swarmpose.gpu.scorer` for the one-launch-per-generation scorer.
"""

from swarmpose.gpu.errors import DeviceError, KernelBuildError

__all__ = ["DeviceError", "KernelBuildError"]
