"""Masks for real captures (``ns2gs-data masks``): an ONNX segmenter with shipped class maps, or
``auto``: masks derived from a first reference NeRF trained without masks."""
