"""``ns2gs-data process images|video``: a raw capture -> posed, metric, undistorted dataset.

Stages (each resumable, see :mod:`.pipeline`): frames (video extraction / image collection, blur
filter) -> features (pycolmap SIFT, CPU) -> matching (sequential or exhaustive) -> mapping
(incremental) -> undistortion (PINHOLE) -> export (COLMAP layout, transforms.json with metric scale
and up from the ground plane, images_2/4/8).
"""
