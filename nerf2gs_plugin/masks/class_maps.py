"""Semantic classes -> our three mask kinds, for Cityscapes (19 train ids), ADE20K (150 classes,
SceneParse150 order, 0-based) and user JSON maps.

A class map is ``{"sky": [...], "ground": [...], "transient": [...]}`` whose entries are class ids
(ints) or class names (strings, resolved through the model's class list). A user file may also
name its ``classes`` (the model's class names in output order). Kinds left out get no pixels.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional, Union

from nerf2gs_plugin.data.dataparser_outputs import MASK_KINDS
from nerf2gs_plugin.errors import ConfigError

CITYSCAPES = (
    "road", "sidewalk", "building", "wall", "fence", "pole", "traffic light", "traffic sign", "vegetation", "terrain",
    "sky", "person", "rider", "car", "truck", "bus", "train", "motorcycle", "bicycle",
)

ADE20K = (
    "wall", "building", "sky", "floor", "tree", "ceiling", "road", "bed", "windowpane", "grass", "cabinet", "sidewalk",
    "person", "earth", "door", "table", "mountain", "plant", "curtain", "chair", "car", "water", "painting", "sofa",
    "shelf", "house", "sea", "mirror", "rug", "field", "armchair", "seat", "fence", "desk", "rock", "wardrobe", "lamp",
    "bathtub", "railing", "cushion", "base", "box", "column", "signboard", "chest of drawers", "counter", "sand", "sink",
    "skyscraper", "fireplace", "refrigerator", "grandstand", "path", "stairs", "runway", "case", "pool table", "pillow",
    "screen door", "stairway", "river", "bridge", "bookcase", "blind", "coffee table", "toilet", "flower", "book", "hill",
    "bench", "countertop", "stove", "palm", "kitchen island", "computer", "swivel chair", "boat", "bar", "arcade machine",
    "hovel", "bus", "towel", "light", "truck", "tower", "chandelier", "awning", "streetlight", "booth",
    "television receiver", "airplane", "dirt track", "apparel", "pole", "land", "bannister", "escalator", "ottoman",
    "bottle", "buffet", "poster", "stage", "van", "ship", "fountain", "conveyer belt", "canopy", "washer", "plaything",
    "swimming pool", "stool", "barrel", "basket", "waterfall", "tent", "bag", "minibike", "cradle", "oven", "ball",
    "food", "step", "tank", "trade name", "microwave", "pot", "animal", "bicycle", "lake", "dishwasher", "screen",
    "blanket", "sculpture", "hood", "sconce", "vase", "traffic light", "tray", "ashcan", "fan", "pier", "crt screen",
    "plate", "monitor", "bulletin board", "shower", "radiator", "glass", "clock", "flag",
)

SHIPPED: dict[str, tuple[tuple[str, ...], dict[str, list[str]]]] = {
    "cityscapes": (CITYSCAPES, {
        "sky": ["sky"],
        "ground": ["road", "sidewalk", "terrain"],
        "transient": ["person", "rider", "car", "truck", "bus", "train", "motorcycle", "bicycle"],
    }),
    "ade20k": (ADE20K, {
        "sky": ["sky"],
        "ground": ["road", "sidewalk", "grass", "earth", "field", "path", "sand", "dirt track", "land", "runway"],
        "transient": ["person", "car", "bus", "truck", "van", "minibike", "bicycle", "animal"],
    }),
}


def shipped_for(num_classes: int) -> Optional[str]:
    """The shipped map whose class count is ``num_classes`` (19 -> cityscapes, 150 -> ade20k)."""
    return next((k for k, (names, _) in SHIPPED.items() if len(names) == num_classes), None)


def resolve(spec: Union[str, Path, dict], num_classes: int, where: Path, model_classes: Optional[list[str]] = None) -> dict[str, list[int]]:
    """Class ids per kind. ``spec``: a shipped name, a JSON file path, or an already-read dict.
    ``where`` names the file in errors. Every id must be below ``num_classes``."""
    names: Optional[list[str]] = list(model_classes) if model_classes else None
    if isinstance(spec, str) and spec.lower() in SHIPPED:
        shipped_names, kinds = SHIPPED[spec.lower()]
        if num_classes != len(shipped_names):
            raise ConfigError(f"class map '{spec}' has {len(shipped_names)} classes but the model outputs {num_classes}", where)
        names, doc = list(shipped_names), dict(kinds)
    elif isinstance(spec, dict):
        doc = spec
    else:
        path = Path(spec)
        where = path
        if not path.is_file():
            raise ConfigError(f"class map file does not exist (or use one of: {', '.join(SHIPPED)})", path)
        try:
            doc = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ConfigError(f"class map is not readable JSON ({e})", path) from None
    if not isinstance(doc, dict):
        raise ConfigError("class map must be a JSON object {sky|ground|transient: [ids or names]}", where)
    doc = dict(doc)
    if "classes" in doc:
        cl = doc.pop("classes")
        if not isinstance(cl, list) or not all(isinstance(c, str) for c in cl):
            raise ConfigError("'classes' must be a list of class names", where)
        names = cl
    unknown = sorted(set(doc) - set(MASK_KINDS))
    if unknown:
        raise ConfigError(f"class map has unknown keys {unknown} (expected sky, ground, transient, classes)", where)
    if not doc:
        raise ConfigError("class map maps no class to sky, ground or transient", where)
    out: dict[str, list[int]] = {}
    for kind, items in doc.items():
        if not isinstance(items, list):
            raise ConfigError(f"'{kind}' must be a list of class ids or names", where)
        ids = []
        for it in items:
            if isinstance(it, bool) or not isinstance(it, (int, str)):
                raise ConfigError(f"'{kind}': {it!r} is neither a class id nor a class name", where)
            if isinstance(it, str):
                if names is None or it not in names:
                    raise ConfigError(f"'{kind}': unknown class name {it!r}" + ("" if names else " (the model names no classes: use ids)"), where)
                it = names.index(it)
            if not 0 <= it < num_classes:
                raise ConfigError(f"'{kind}': class id {it} is outside the model's {num_classes} classes", where)
            ids.append(int(it))
        out[kind] = ids
    return out
