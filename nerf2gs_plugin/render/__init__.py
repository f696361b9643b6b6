"""Rendering a trained run along a camera path (``ns2gs-render``): the paths (one module per kind,
one registry), frames (outputs coloured and tiled, runs side by side), the video / PNG writer and
the measures that need no ground truth from above (holes, near-camera floaters)."""
