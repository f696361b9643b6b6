"""Masks for real captures (``ns2gs-data masks``): the mask files' kinds (``maskless``), an ONNX
segmenter with shipped class maps, or ``auto``: masks derived from the renders of a first reference
NeRF trained without masks (``from_renders`` and ``auto`` turn renders into masks; ``mask_reference``,
``auto_masks`` and ``make_masks`` train or load that reference, a floor above the methods), and
their evaluation against ground truth (``evaluate``)."""
