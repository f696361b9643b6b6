"""2DGS's registered configuration.

Default (CPU scale): 3000 steps, the splatfacto refinement schedule, depth distortion from step
300 and normal consistency from step 700 (2DGS: 3000 and 7000 of 30000).

Paper scale (for a GPU): the splatfacto paper flags (see ``methods/splatfacto/config.py``) plus
``--pipeline.model.dist-start 3000 --pipeline.model.normal-start 7000``; :func:`paper_scale`
applies them and the ``paper`` preset is that config.
"""

from __future__ import annotations

import dataclasses

from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.engine.pipeline import PipelineConfig
from nerf2gs_plugin.engine.trainer_config import TrainerConfig
from nerf2gs_plugin.methods.splatfacto.config import gaussian_optimizers
from nerf2gs_plugin.methods.splatfacto.config import paper_scale as splatfacto_paper_scale
from nerf2gs_plugin.methods.two_dgs.model import TwoDGSModelConfig
from nerf2gs_plugin.registry import MethodSpecification, Preset

DEFAULT_STEPS = 3000


def paper_scale(config: TrainerConfig) -> TrainerConfig:
    config = splatfacto_paper_scale(config)
    model = dataclasses.replace(config.pipeline.model, dist_start=3000, normal_start=7000)
    return dataclasses.replace(config, pipeline=dataclasses.replace(config.pipeline, model=model))


two_dgs_config = TrainerConfig(
    method_name="2dgs",
    max_num_iterations=DEFAULT_STEPS,
    steps_per_eval_image=500,
    steps_per_save=1000,
    pipeline=PipelineConfig(datamanager=FullImageDataManagerConfig(), model=TwoDGSModelConfig()),
    optimizers=gaussian_optimizers(DEFAULT_STEPS),
)

two_dgs_method = MethodSpecification(
    config=two_dgs_config,
    description="2DGS: 2D Gaussian surfels with depth distortion and normal consistency, CPU-scale defaults.",
    presets={"paper": Preset(
        paper_scale, "2DGS at the paper's scale (30k steps; for a GPU).")},
)
