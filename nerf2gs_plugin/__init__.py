"""nerf2gs: train Gaussian-splatting methods on images rendered by a street-scene NeRF."""

__version__ = "0.1.0"
