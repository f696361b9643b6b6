"""Masks for real captures: the mask files' kinds (``maskless``), an ONNX segmenter with shipped
class maps, masks derived from the renders of a first reference NeRF trained without masks
(``from_renders`` and ``auto`` turn renders into masks, ``motion`` adds moving objects), and their
evaluation against ground truth (``evaluate``). The stage that writes them for a dataset and trains
or loads that reference (``ns2gs-data masks``) is :mod:`nerf2gs_plugin.masking`, a floor above the
methods."""
