"""The views no training camera took: the bird's-eye and the lane-shift splits of the synthetic
street, and their mean ("extrapolated"), which the tables and ns2gs-eval report beside the splits."""

from __future__ import annotations

from typing import Optional

EXTRAPOLATED_SPLITS = ("bev_1", "bev_2", "lane_2", "lane_4")
EXTRAPOLATED = "extrapolated"  # the column and row name


def extrapolated_mean(results: dict, metric: str) -> Optional[float]:
    """Mean of ``metric`` over :data:`EXTRAPOLATED_SPLITS` in ``results`` (split -> metrics); None
    unless every one of them has it, so a dataset without lane views shows n/a, not a bird's-eye mean."""
    vals = [results.get(s, {}).get(metric) for s in EXTRAPOLATED_SPLITS]
    if not all(isinstance(v, (int, float)) for v in vals):
        return None
    return sum(vals) / len(vals)


def extrapolated_summary(results: dict) -> Optional[dict]:
    """``{psnr, ssim, lpips, psnr_ground, splits}`` means over the extrapolated splits (None without them)."""
    if extrapolated_mean(results, "psnr") is None:
        return None
    out: dict = {m: extrapolated_mean(results, m) for m in ("psnr", "ssim", "lpips", "psnr_ground")}
    return {**out, "splits": list(EXTRAPOLATED_SPLITS)}
