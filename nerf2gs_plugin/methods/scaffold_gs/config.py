"""Scaffold-GS's registered configuration.

Default (CPU scale): 3000 steps; statistics from step 50, anchor growing/pruning every 100 steps
from 150 to 1500; k = 10 offsets, 32-d features, voxel size = median nearest-neighbour distance
of the sparse points; anchors grow to at most 1.25x the initial ones (and 20k).

Paper scale (Scaffold-GS defaults, for a GPU)::

    ns2gs-train scaffold-gs --data DATA --max-num-iterations 30000 \\
      --pipeline.model.start-stat 500 --pipeline.model.update-from 1500 \\
      --pipeline.model.update-until 15000 --pipeline.model.max-anchors 0 --pipeline.model.anchor-growth 0 \\
      --optimizers.offsets.max-steps 30000 ... (every scheduled group: max-steps 30000)

(:func:`paper_scale` applies them; the ``paper`` preset is that config.)
"""

from __future__ import annotations

import dataclasses

from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.engine.optimizers import OptimizerConfig
from nerf2gs_plugin.engine.pipeline import PipelineConfig
from nerf2gs_plugin.engine.trainer_config import TrainerConfig
from nerf2gs_plugin.methods.scaffold_gs.model import ScaffoldGSModelConfig
from nerf2gs_plugin.registry import MethodSpecification, Preset

DEFAULT_STEPS = 3000
PAPER_STEPS = 30000


def scaffold_optimizers(max_steps: int) -> dict[str, OptimizerConfig]:
    """Scaffold-GS's learning rates (anchors are fixed: lr 0, no optimizer state)."""
    return {
        "anchors": OptimizerConfig(lr=0.0),
        "offsets": OptimizerConfig(lr=0.01, lr_final=1e-4, max_steps=max_steps, eps=1e-15),
        "anchor_feat": OptimizerConfig(lr=0.0075, eps=1e-15),
        "scaling": OptimizerConfig(lr=0.007, eps=1e-15),
        "mlp_opacity": OptimizerConfig(lr=0.002, lr_final=2e-5, max_steps=max_steps, eps=1e-15),
        "mlp_cov": OptimizerConfig(lr=0.004, lr_final=4e-3, max_steps=max_steps, eps=1e-15),
        "mlp_color": OptimizerConfig(lr=0.008, lr_final=5e-5, max_steps=max_steps, eps=1e-15),
        "appearance": OptimizerConfig(lr=0.05, lr_final=5e-4, max_steps=max_steps, eps=1e-15),
        "background": OptimizerConfig(lr=1e-2, eps=1e-15),
    }


def paper_scale(config: TrainerConfig) -> TrainerConfig:
    model = dataclasses.replace(config.pipeline.model, start_stat=500, update_from=1500, update_until=15000,
                                max_anchors=0, anchor_growth=0.0, pixel_steps_per_anchor=0.0,
                                num_random=50000)
    return dataclasses.replace(
        config, max_num_iterations=PAPER_STEPS, steps_per_save=2000, steps_per_eval_image=1000,
        pipeline=dataclasses.replace(config.pipeline, model=model), optimizers=scaffold_optimizers(PAPER_STEPS),
    )


scaffold_gs_config = TrainerConfig(
    method_name="scaffold-gs",
    max_num_iterations=DEFAULT_STEPS,
    steps_per_eval_image=500,
    steps_per_save=1000,
    pipeline=PipelineConfig(datamanager=FullImageDataManagerConfig(), model=ScaffoldGSModelConfig()),
    optimizers=scaffold_optimizers(DEFAULT_STEPS),
)

scaffold_gs_method = MethodSpecification(
    config=scaffold_gs_config,
    description="Scaffold-GS: anchor-based neural Gaussians with MLP decoders, CPU-scale defaults.",
    presets={"paper": Preset(
        paper_scale, "Scaffold-GS at the paper's scale (30k steps; for a GPU).")},
)
