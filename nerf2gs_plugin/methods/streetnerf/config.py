"""StreetNeRF's registered configurations.

Default (CPU scale: the synthetic street at ~200x112 px on 2 CPU cores, well under 20 minutes):
see ``DEFAULT_STEPS``, 1024 rays per batch, a 12-level 2^15 hash grid, proposal rounds 48 -> 24 ->
24 fine samples. The learning rates decay over ``max_num_iterations`` whatever it is set to.
Without the sparse-point depth loss the upper facades stay half-built. Times and PSNR: docs/results
(`ns2gs-bench paper-table`); ground regularisation on vs off: `ns2gs-bench ablation`.

Paper scale (the ``paper`` preset, :func:`paper_scale`): Zip-NeRF/nerfacto-like capacity for
a GPU: 16 levels x 2^19 entries up to 4096, proposal samples 256 -> 96 -> 48, 4096 rays, 25k steps.
"""

from __future__ import annotations

import dataclasses

from nerf2gs_plugin.datamanagers.rays import RayDataManagerConfig
from nerf2gs_plugin.engine.optimizers import OptimizerConfig
from nerf2gs_plugin.engine.pipeline import PipelineConfig
from nerf2gs_plugin.engine.trainer_config import TrainerConfig
from nerf2gs_plugin.methods.streetnerf.model import StreetNeRFModelConfig
from nerf2gs_plugin.registry import MethodSpecification, Preset

DEFAULT_STEPS = 3000
PAPER_STEPS = 25000


def streetnerf_optimizers(max_steps: int) -> dict[str, OptimizerConfig]:
    """nerfacto's Adam settings (lr 1e-2, eps 1e-15) with exponential decay to a tenth at the end: nerfacto
    decays over 200k steps, so its lr barely moves in a few thousand; decaying to 1e-4 in 3000 steps
    starves the hash tables (no learning on the tiny scene). ``camera_opt`` is used only with
    ``--pipeline.model.camera-optimizer.mode SO3xR3``: nerfstudio's pose-refinement rate (6e-4), decayed
    to a tenth over the run like the others."""
    return {
        "fields": OptimizerConfig(lr=1e-2, eps=1e-15, lr_final=1e-3, max_steps=max_steps),
        "proposal_networks": OptimizerConfig(lr=1e-2, eps=1e-15, lr_final=1e-3, max_steps=max_steps),
        "sky_appearance": OptimizerConfig(lr=5e-3, eps=1e-15, lr_final=5e-4, max_steps=max_steps),
        "camera_opt": OptimizerConfig(lr=6e-4, eps=1e-15, lr_final=6e-5, max_steps=max_steps),
    }


def paper_scale(config: TrainerConfig) -> TrainerConfig:
    """Zip-NeRF/nerfacto-like capacity and step count, for a GPU."""
    model = dataclasses.replace(
        config.pipeline.model, num_levels=16, log2_hashmap_size=19, max_res=4096, sh_degree=4,
        num_proposal_samples=(256, 96), num_nerf_samples=48, proposal_log2_hashmap_size=17, proposal_max_res=(128, 256),
        proposal_anneal_steps=1000, ground_start_step=1000, eval_chunk=16384,
    )
    dm = dataclasses.replace(config.pipeline.datamanager, rays_per_batch=4096)
    return dataclasses.replace(
        config, max_num_iterations=PAPER_STEPS, steps_per_save=2000, steps_per_eval_image=1000,
        pipeline=dataclasses.replace(config.pipeline, datamanager=dm, model=model), optimizers=streetnerf_optimizers(PAPER_STEPS),
    )


streetnerf_config = TrainerConfig(
    method_name="streetnerf",
    max_num_iterations=DEFAULT_STEPS,
    steps_per_eval_image=500,
    steps_per_save=1000,
    pipeline=PipelineConfig(datamanager=RayDataManagerConfig(rays_per_batch=1024), model=StreetNeRFModelConfig()),
    optimizers=streetnerf_optimizers(DEFAULT_STEPS),
)

streetnerf_method = MethodSpecification(
    config=streetnerf_config,
    description="StreetNeRF: segmentation-guided street NeRF (hash grid, proposals, sky/ground/transient masks, appearance); CPU-scale defaults.",
    presets={"paper": Preset(
        paper_scale, "StreetNeRF at Zip-NeRF-like capacity (16x2^19 hash grid, 256/96/48 samples, 4096 rays, 25k steps; for a GPU).")},
)
