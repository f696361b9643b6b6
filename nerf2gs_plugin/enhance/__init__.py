"""Training our own enhancer (``ns2gs-enhance train``): pairs from a reference run, degradations,
the residual U-Net and its ONNX export. Running an enhancer is :mod:`nerf2gs_plugin.enhancers`."""
