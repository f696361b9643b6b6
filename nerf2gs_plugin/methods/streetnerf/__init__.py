"""StreetNeRF: the segmentation-guided street NeRF used as the reference method (Sec. 2.2)."""
