"""The ``--augment.*`` flags, defined beside the trainer's config that holds them
(:mod:`nerf2gs_plugin.engine.augment_config`) and named here for the augmentation's modules."""

from nerf2gs_plugin.engine.augment_config import FAMILY_FIELDS, AugmentConfig, LaneShiftConfig, PosesFileConfig, RaiseConfig

__all__ = ["FAMILY_FIELDS", "AugmentConfig", "LaneShiftConfig", "PosesFileConfig", "RaiseConfig"]
