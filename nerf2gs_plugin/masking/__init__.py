"""The masking stage (``ns2gs-data masks``): writes a dataset's sky / ground / transient masks with an
ONNX segmenter, or with ``--segmenter auto`` from a first reference of the capture itself: a short
StreetNeRF trained without masks (``mask_reference``), whose renders (``auto_masks``) the maths of
:mod:`nerf2gs_plugin.masks` turns into masks. ``make_masks`` is the stage's config and entry point.
It trains and loads runs, so it sits above the methods; the masks' files and maths sit below them."""
