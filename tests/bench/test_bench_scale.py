"""ns2gs-bench scale's parts: the stitched longer street is one readable dataset with its streets
side by side, the fit recovers a known law (residual 0), and the projection's block arithmetic."""

from __future__ import annotations

import json

import pytest

from nerf2gs_plugin.data import parse_dataset
from nerf2gs_bench import scale as bench_scale


def test_long_street_stitches_segments(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_scale, "SEGMENT_FRAMES", 4)
    monkeypatch.setattr(bench_scale, "SEGMENT_POINTS", 50)
    data = bench_scale.long_street(tmp_path, 2, 24, 16)
    meta = json.loads((data / "transforms.json").read_text())
    assert len(meta["frames"]) == 8 and not (data / "images").exists()  # referenced, not copied
    xs = [f["transform_matrix"][0][3] for f in meta["frames"]]
    assert min(xs[4:]) - max(xs[:4]) > bench_scale.SEGMENT_SPACING - 2 * 24.0 - 1  # second street beyond the first
    out = parse_dataset(data, "train")
    assert len(out.image_filenames) == 8 and len(out.points3D_xyz) == 100
    assert set(parse_dataset(data, "street").image_filenames) & set(out.image_filenames) == set()


def test_fit_recovers_a_known_law():
    rows = [{"t": 0.5 + 2e-6 * p + 1e-5 * n, "pixels": p, "primitives": n} for p, n in ((1e4, 100), (4e4, 900), (9e4, 400), (2e4, 3000))]
    law = bench_scale.fit(rows, "t", ["pixels", "primitives"])
    assert law["coef"] == pytest.approx([0.5, 2e-6, 1e-5], rel=1e-6)
    assert law["rms_relative_residual"] < 1e-9
    assert bench_scale.predict(law, pixels=1e5, primitives=0) == pytest.approx(0.7)


def test_projection_blocks_arithmetic():
    law = {"time": {"coef": [1.0, 0.0, 0.0], "terms": ["1", "pixels", "primitives"]},
           "rss": {"coef": [100.0, 0.0, 0.0], "terms": ["1", "image_pixels", "primitives"]}}
    proj = bench_scale.projection([], {"splatfacto": law}, {"splatfacto": 3000})
    one, block = proj["splatfacto"]["one run"], proj["splatfacto"]["per block"]
    assert one["images"] == pytest.approx(1000 / 48 * 30)
    assert one["steps"] == pytest.approx(3000 * one["images"] / 60)  # one image per step: steps follow the images
    assert block["images"] == pytest.approx(one["images"] / bench_scale.BLOCKS * 1.4)
    assert proj["splatfacto"]["blocks one after another, hours"] == pytest.approx(1.4 * one["hours"])
