"""Hand-drawn moving-object labels of real frames (``benchmarks/validation/labels/<name>.json``) as masks.

A labels file holds, per frame (keyed by the trailing digits of the source frame's name), polygons in the
source frame's pixels (``size``; or in a resized crop of it: ``size``, ``source_size`` and ``source_rows``, the
source rows the crop kept): each moving object (one polygon under its own name, or a list of them
under ``moving``), ``ignore`` regions (objects whose motion cannot be told: they count neither way) and,
for the whole capture, the ``ego`` car's outline (a bonnet). What the benches do with them: the masks
stage's transient masks of training frames scored against the moving objects (:func:`moving_scores`), and
held-out frames scored on their static pixels only (:func:`labelled_view`, read by ``ns2gs-eval``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

LABELS_DIR = Path(__file__).resolve().parents[1] / "benchmarks" / "validation" / "labels"
IGNORE, EGO = "ignore", "ego"


def load_labels(name: str) -> dict:
    """``LABELS_DIR/<name>.json``; one clear line when it is not there."""
    import json

    from nerf2gs_plugin.errors import DataError

    path = LABELS_DIR / f"{name}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise DataError(f"hand labels '{name}' unreadable ({e.__class__.__name__})", path) from e


def merged_labels(names: Sequence[str]) -> dict:
    """One labels document of several label sets of the same frames, each frame's polygons in source pixels
    (:func:`in_source_pixels`; where two sets label a frame, the first named wins)."""
    from nerf2gs_plugin.errors import DataError

    out: dict = {}
    for name in names:
        lab = in_source_pixels(load_labels(name))
        if out and out["size"] != lab["size"]:
            raise DataError(f"hand labels '{name}' are of {lab['size']} source frames, the others of {out['size']}", LABELS_DIR / f"{name}.json")
        out = {**lab, **out, "frames": {**lab["frames"], **out.get("frames", {})}}
    return out


def frame_key(stem: str) -> Optional[str]:
    """The labels' key of a frame: its name's trailing digits (``frame_000031`` / ``000031`` -> ``000031``)."""
    m = re.search(r"(\d+)$", stem)
    return m.group(1)[-6:] if m else None


def polygons(value: list) -> list[np.ndarray]:
    """One polygon (``[[x, y], ...]``) or a list of them, as int-able arrays."""
    if not value:
        return []
    first = value[0]
    nested = isinstance(first, (list, tuple)) and first and isinstance(first[0], (list, tuple))
    return [np.asarray(p, np.float64) for p in (value if nested else [value])]


def _to_source(labels: dict) -> np.ndarray:
    """Label pixels -> source pixels (x, y): labels drawn on a resized crop of the source say so (``source_size``,
    ``source_rows``); others are in source pixels already."""
    src_w, src_h = labels.get("source_size", labels["size"])
    return np.array([src_w / labels["size"][0], labels.get("source_rows", src_h) / labels["size"][1]])


def in_source_pixels(labels: dict) -> dict:
    """``labels`` with every polygon in the source frame's pixels (``size`` the source's)."""
    to_src = _to_source(labels)
    frames = {key: {what: [(p * to_src).tolist() for p in polygons(v)] for what, v in entry.items()}
              for key, entry in labels["frames"].items()}
    out = {k: v for k, v in labels.items() if k not in ("source_size", "source_rows")}
    return {**out, "size": list(labels.get("source_size", labels["size"])), "frames": frames}


def frame_masks(entry: dict, labels: dict, size: tuple[int, int], crop_rows: Optional[int] = None) -> tuple[np.ndarray, np.ndarray]:
    """``(moving, leave_out)`` bool masks ``[h, w]`` of one labelled frame at ``size`` (w, h): the source
    frame's first ``crop_rows`` rows (all by default) resized. ``leave_out``: its ignore regions and the ego car."""
    import cv2

    src_w, src_h = labels.get("source_size", labels["size"])
    scale = _to_source(labels) * [size[0] / src_w, size[1] / (crop_rows or src_h)]
    moving = np.zeros(size[::-1], np.uint8)
    leave_out = np.zeros(size[::-1], np.uint8)
    extra = [(EGO, labels[EGO])] if labels.get(EGO) else []
    for what, value in [*entry.items(), *extra]:
        target = leave_out if what in (IGNORE, EGO) else moving
        for p in polygons(value):
            cv2.fillPoly(target, [np.round(p * scale).astype(np.int32)], 1)
    return moving > 0, leave_out > 0


def split_images(capture: Path, split: str) -> list[Path]:
    """The capture's images of ``split`` (``train`` / ``test``), as the dataparser holds the frames out."""
    from nerf2gs_plugin.data import dataparser_config

    return sorted(f.image for f in dataparser_config(capture).raw_frames().get(split, []))


def _labelled_masks(capture: Path, labels: dict, key_of: Callable[[str], Optional[str]]):
    """``(stem, labels key, the masks stage's transient mask)`` of each labelled training frame that has one."""
    import cv2

    for img in split_images(capture, "train"):
        key, mask_path = key_of(img.stem), capture / "masks" / "transient" / f"{img.stem}.png"
        if key in labels["frames"] and mask_path.is_file():
            yield img.stem, key, cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE) > 0


def _counts(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(intersection, union, predicted, true) pixel counts."""
    return np.array([int((pred & truth).sum()), int((pred | truth).sum()), int(pred.sum()), int(truth.sum())])


def moving_scores(capture: Path, labels: dict, crop_rows: Optional[int] = None,
                  key_of: Callable[[str], Optional[str]] = frame_key) -> Optional[dict]:
    """IoU, precision and recall of the masks stage's ``masks/transient/`` against the moving objects, pooled
    over the labelled training frames (the masks stage marks those) and per frame (``per_frame``); None when
    none is labelled. ``key_of``:
    a frame's labels key from its image stem (:func:`frame_key`; a video's frames are named by their index)."""
    counts, frames, per_frame = np.zeros(4, np.int64), [], {}
    for stem, key, est in _labelled_masks(capture, labels, key_of):
        moving, leave_out = frame_masks(labels["frames"][key], labels, (est.shape[1], est.shape[0]), crop_rows)
        c = _counts(est & ~leave_out, moving & ~leave_out)
        counts += c
        frames.append(stem)
        per_frame[stem] = _ratios(c)
    if not frames:
        return None
    return {**_ratios(counts), "frames": frames, "per_frame": per_frame}


def completion_bound(capture: Path, labels: dict, crop_rows: Optional[int], key_of: Callable[[str], Optional[str]], hit: float) -> dict:
    """Pooled IoU / precision / recall of the capture's transient masks (as :func:`moving_scores` scores them)
    with every labelled object (one named polygon of a frame) that they cover by more than ``hit`` of its pixels
    marked whole: what completing the objects the masks find could give."""
    counts = np.zeros(4, np.int64)
    for _, key, est in _labelled_masks(capture, labels, key_of):
        size, entry = (est.shape[1], est.shape[0]), labels["frames"][key]
        keep = ~frame_masks(entry, labels, size, crop_rows)[1]
        pred, truth = est & keep, np.zeros_like(est)
        for name, value in entry.items():
            if name in (IGNORE, EGO):
                continue
            obj = frame_masks({name: value}, labels, size, crop_rows)[0] & keep
            truth |= obj
            if obj.any() and (pred & obj).sum() > hit * obj.sum():
                pred |= obj
        counts += _counts(pred, truth)
    return _ratios(counts)


def _ratios(counts: np.ndarray) -> dict:
    """IoU, precision and recall from (intersection, union, predicted, true) pixel counts."""
    i, u, p, t = (int(x) for x in counts)
    return {"iou": i / max(u, 1), "precision": i / max(p, 1), "recall": i / max(t, 1)}


def labelled_view(capture: Path, labels: dict, out: Path, crop_rows: Optional[int] = None) -> list[str]:
    """``out``: the capture's files linked, its masks too, the held-out frames' transient masks replaced by
    the labels (moving, ignore and ego: what leaves a static score) where they have them; returns those
    frames' image stems. ``ns2gs-eval --data out`` then scores their static pixels by hand labels."""
    import cv2

    out.mkdir(parents=True, exist_ok=True)
    for f in capture.iterdir():
        if f.name != "masks":
            (out / f.name).symlink_to(f.resolve())
    for kind in ("sky", "ground", "transient"):
        src = capture / "masks" / kind
        (out / "masks" / kind).mkdir(parents=True, exist_ok=True)
        if src.is_dir():
            for m in src.iterdir():
                (out / "masks" / kind / m.name).symlink_to(m.resolve())
    stems = []
    for img in split_images(capture, "test"):
        key = frame_key(img.stem)
        if key not in labels["frames"]:
            continue
        h, w = cv2.imread(str(img)).shape[:2]
        moving, leave_out = frame_masks(labels["frames"][key], labels, (w, h), crop_rows)
        dst = out / "masks" / "transient" / f"{img.stem}.png"
        dst.unlink(missing_ok=True)
        cv2.imwrite(str(dst), ((moving | leave_out) * 255).astype(np.uint8))
        stems.append(img.stem)
    return stems
