"""The lab beside the product: ``ns2gs-bench`` and the benches it runs (paper table, ablation,
speed-quality, stability, model size, rasterizer, field, faults, real captures, scale, blocks).

It sits above every layer of ``nerf2gs_plugin``: benches train and evaluate runs through the
package's public modules, and nothing in ``nerf2gs_plugin`` imports this package.
"""
