"""``ns2gs-bench street-level``'s pure parts: the validation / test split of the held-out frames, the regions
of a frame from a reference render, and where the extra squared error sits."""

import math

import pytest
import torch

from nerf2gs_bench import street_level as sl
from nerf2gs_plugin.errors import DataError


def test_held_out_frames_alternate_between_validation_and_test_in_name_order():
    roles = sl.split_roles(["0016.png", "0000.png", "0008.png", "0024.png", "0032.png"])
    assert [roles[n] for n in sorted(roles)] == ["val", "test", "val", "test", "val"]


def test_regions_split_sky_ground_rest_and_near_far():
    # a camera 1 unit above the plane z=0 looking along +x: top row up into the sky, bottom rows down to the road
    h, w = 4, 2
    dirs = torch.zeros(h, w, 3)
    dirs[..., 0] = 1.0
    dirs[0, :, 2], dirs[1, :, 2], dirs[2, :, 2], dirs[3, :, 2] = 0.5, -0.05, -0.5, -0.5
    dirs = dirs / dirs.norm(dim=-1, keepdim=True)
    acc = torch.ones(h, w)
    acc[0] = 0.0  # nothing rendered above the horizon: sky
    depth = torch.full((h, w), 5.0)  # row 1: a wall 5 units ahead, 0.75 above the road
    depth[2:] = 1.0 / float(-dirs[2, 0, 2])
    view = {"acc": acc, "dirs": dirs, "depth": depth, "origin": torch.tensor([0.0, 0.0, 1.0])}
    m = sl.region_masks(view, torch.tensor([0.0, 0.0, 1.0]), 0.0, camera_height=1.0)
    assert m["sky"][0].all() and not m["sky"][1:].any()
    assert m["ground"][2:].all() and not m["ground"][:2].any()  
    assert m["rest"][1].all() and not m["rest"][2:].any()
    assert m["near"][2:].all() and m["far"][1].all() and not (m["near"] | m["far"])[0].any()
    parts = m["sky"].int() + m["ground"].int() + m["rest"].int()
    assert (parts == 1).all()


def test_loss_shares_of_sky_ground_rest_sum_to_one():
    target = {"all": {"sse": 10.0}, "sky": {"sse": 2.0}, "ground": {"sse": 5.0}, "rest": {"sse": 3.0}}
    variant = {"all": {"sse": 14.0}, "sky": {"sse": 2.0}, "ground": {"sse": 8.0}, "rest": {"sse": 4.0}}
    s = sl.loss_shares(variant, target)
    assert s == {"sky": 0.0, "ground": 0.75, "rest": 0.25}


def test_summary_psnr_is_the_mean_over_the_role_s_frames():
    errs = {"a": {"all": [0.01 * 4, 4]}, "b": {"all": [0.0001 * 4, 4]}, "c": {"all": [1.0 * 4, 4]}}
    s = sl.summarise(errs, {"a": "val", "b": "test", "c": "val"}, "val")
    assert s["all"]["psnr"] == pytest.approx((20.0 + 0.0) / 2)
    assert s["all"]["sse"] == pytest.approx(4.04)


def test_missing_real_captures_runs_are_named(tmp_path):
    with pytest.raises(DataError) as e:
        sl.find_reference(tmp_path, "kitti")
    assert "real-captures" in str(e.value)


def test_a_variant_s_model_overrides_reach_the_splatfacto_config_beside_the_step_schedule():
    from nerf2gs_bench.paper import step_overrides
    from nerf2gs_plugin.registry import get_method
    from nerf2gs_plugin.utils.config import apply_plain

    base = {**step_overrides("splatfacto", 700), "seed": 42}
    ov = sl.variant_overrides(base, sl.VARIANTS["sky_alpha 0.5"])
    cfg = apply_plain(get_method("splatfacto").config, ov, where="test")
    assert cfg.pipeline.model.sky_alpha_weight == 0.5
    assert ov["pipeline"]["model"]["strategy"] == base["pipeline"]["model"]["strategy"]
    assert sl.variant_overrides(base, sl.VARIANTS["default"]) == base
    assert get_method("splatfacto").config.pipeline.model.sky_alpha_weight != 0.5
    assert "augment" not in sl.VARIANTS["target sky_alpha 0"]  # the target alone, its sky weight changed


def test_frames_are_scored_at_the_downscale_the_run_trained_at():
    """The held-out frames' names carry the downscale (undistorted copies): a run read at another size matches no frame."""
    from nerf2gs_bench.real_photos import RealPhotosOptions, run_overrides
    from nerf2gs_plugin.registry import get_method
    from nerf2gs_plugin.utils.config import apply_plain

    ov = run_overrides(RealPhotosOptions(images=".", downscale=2.0, holdout_every=8), "splatfacto", 700)
    cfg = apply_plain(get_method("splatfacto").config, ov, where="test")
    assert sl.run_downscale(cfg) == 2.0
    assert sl.run_downscale(get_method("splatfacto").config) == 1.0


def test_the_synthetic_street_trains_a_variant_s_steps_factor(monkeypatch, tmp_path):
    import nerf2gs_bench.paper as paper

    plans = []

    def fake_plan(plan, data, runs_root, log=None, name=""):
        plans.extend(plan)
        return {s.label: {"results": {"street": {"psnr": 20.0}}} for s in plan}

    monkeypatch.setattr(paper, "run_plan", fake_plan)
    sl.synthetic(tmp_path, tmp_path, ["view-downscale 2, input samples matched"], seeds=(42,))
    steps = {s.label: s.overrides["max_num_iterations"] for s in plans if s.method == "splatfacto"}
    base = sl.SYNTHETIC_STEPS["splatfacto"]
    assert steps == {"target, seed 42": base, "view-downscale 2, input samples matched, seed 42": round(base * 1.8)}
