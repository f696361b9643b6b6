"""Neural-field building blocks: hash-grid encoding (C++/OpenMP CPU kernel + torch reference),
MLPs, scene contraction, sky model and per-image appearance transforms."""

from nerf2gs_plugin.fields.appearance import AppearanceTransforms
from nerf2gs_plugin.fields.contraction import contract, contraction_scale, to_box_frame, to_grid_unit
from nerf2gs_plugin.fields.hash_encoding import HashEncoding, HashGridSpec, hash_encode, hash_encode_torch, load_kernel
from nerf2gs_plugin.fields.mlp import MLP, trunc_exp
from nerf2gs_plugin.fields.sky import SkyModel
from nerf2gs_plugin.fields.street_field import ProposalField, StreetField

__all__ = [
    "AppearanceTransforms", "HashEncoding", "HashGridSpec", "MLP", "ProposalField", "SkyModel", "StreetField",
    "contract", "contraction_scale", "hash_encode", "hash_encode_torch", "load_kernel",
    "to_box_frame", "to_grid_unit", "trunc_exp",
]
