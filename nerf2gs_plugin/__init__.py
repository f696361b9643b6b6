"""nerf2gs: train Gaussian-splatting methods on images rendered by a street-scene NeRF."""

import os as _os

# OpenMP workers that spin-wait between parallel regions steal the few cores of a shared machine
# from the threads doing the work (torch ops and the C++ kernels both use OpenMP): with the default
# (active) policy the rasterizer runs many times slower on a loaded machine. Read by the
# OpenMP runtime when torch loads, so it only applies when this package is imported first (the
# ns2gs-* commands); set OMP_WAIT_POLICY yourself to override.
_os.environ.setdefault("OMP_WAIT_POLICY", "passive")

__version__ = "0.1.0"
