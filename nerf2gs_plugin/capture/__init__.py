"""Capture tools that train or load runs (at the eval/enhance layer): the first reference of
``ns2gs-data masks --segmenter auto``, the masks derived from its renders, and ``make_masks``.
The pure parts (class maps, the ONNX segmenter, masks from renders) live in ``data/masks/``."""
