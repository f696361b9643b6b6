"""2DGS: surfel splatting with depth distortion and normal consistency losses."""
