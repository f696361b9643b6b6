"""Splatfacto (nerfstudio's 3DGS) on this project's rasterizer."""
