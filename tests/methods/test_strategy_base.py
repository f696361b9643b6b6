"""The Strategy contract: every densification strategy implements it with a declared gradient
key, and the splatting models drive whatever strategy they hold through it alone."""

import pytest
import torch
from torch import nn

from nerf2gs_plugin.methods.scaffold_gs.anchors import AnchorStrategy
from nerf2gs_plugin.methods.scaffold_gs.model import ScaffoldGSModelConfig
from nerf2gs_plugin.methods.splatfacto.strategy import DefaultStrategy, DefaultStrategyConfig, MCMCStrategy, MCMCStrategyConfig
from nerf2gs_plugin.methods.strategy_base import Strategy
from nerf2gs_plugin.methods.two_dgs.model import SurfelStrategy


def test_strategy_is_abstract():
    with pytest.raises(TypeError):
        Strategy()


@pytest.mark.parametrize("strategy, key", [
    (DefaultStrategy(DefaultStrategyConfig()), "means2d"),
    (MCMCStrategy(MCMCStrategyConfig()), "means2d"),
    (SurfelStrategy(DefaultStrategyConfig()), "gradient_2dgs"),
    (AnchorStrategy(ScaffoldGSModelConfig(), 0.1), "means2d"),
])
def test_every_strategy_declares_its_gradient(strategy, key):
    assert isinstance(strategy, Strategy) and strategy.grad_key == key
    leaf = torch.zeros(1, 3, 2, requires_grad=True)
    other = leaf * 1.0
    info = {key: leaf * 2.0, **({"means2d": other} if key != "means2d" else {})}
    strategy.step_pre_backward(nn.ParameterDict(), None, 0, info)
    (info[key].sum() + other.sum()).backward()
    assert info[key].retains_grad and info[key].grad is not None  # the declared key's gradient is kept
    if key != "means2d":
        assert not other.retains_grad  # and no other


def _params(n):
    g = torch.Generator().manual_seed(0)
    return nn.ParameterDict({"means": nn.Parameter(torch.randn(n, 3, generator=g)), "scales": nn.Parameter(torch.full((n, 2), -6.0)),
                             "quats": nn.Parameter(torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1)),
                             "opacities": nn.Parameter(torch.full((n,), 2.0))})


def test_post_backward_accumulates_from_the_declared_key_then_refines():
    """SurfelStrategy reads ``gradient_2dgs`` (not ``means2d``) and clones on its refine step."""
    n = 5
    params = _params(n)
    strat = SurfelStrategy(DefaultStrategyConfig(warmup_length=0, refine_every=10, reset_alpha_every=0))
    signal = torch.zeros(1, n, 2, requires_grad=True)
    centres = torch.zeros(1, n, 2, requires_grad=True)
    info = {"gradient_2dgs": signal * 1.0, "means2d": centres * 1.0, "radii": torch.ones(1, n), "width": 20, "height": 20}
    strat.step_pre_backward(params, None, 9, info)
    weights = torch.zeros(1, n, 2)
    weights[0, :2] = 1.0  # only the first two surfels have a large 2DGS gradient
    ((info["gradient_2dgs"] * weights).sum() + 100 * info["means2d"].sum()).backward()
    assert strat.step_post_backward(params, None, 9, info) == {"cloned": 0, "split": 0, "pruned": 0}  # not a refine step
    assert torch.equal(strat.grad_accum > 0, torch.tensor([True, True, False, False, False]))
    out = strat.step_post_backward(params, None, 10, None)
    assert out["cloned"] == 2 and params["means"].shape[0] == n + 2
    assert strat.grad_accum.shape[0] == n + 2 and float(strat.grad_accum.sum()) == 0.0
    strat.initialize_state()
    assert strat.grad_accum is None


def test_models_drive_any_strategy_through_the_contract(tiny_scene):
    """Splatfacto calls whatever Strategy it holds: pre-backward while rendering, post-backward
    after the optimizer step, with the render's info."""
    from nerf2gs_plugin.engine.callbacks import TrainingCallbackAttributes, TrainingCallbackLocation as Loc
    from nerf2gs_plugin.engine.optimizers import Optimizers
    from nerf2gs_plugin.engine.pipeline import Pipeline
    from nerf2gs_plugin.registry import get_method

    class Recording(Strategy):
        grad_key = "means2d"

        def __init__(self):
            self.calls = []

        def initialize_state(self):
            self.calls.append("init")

        def step_pre_backward(self, params, optimizers, step, info):
            self.calls.append(("pre", step))
            super().step_pre_backward(params, optimizers, step, info)

        def step_post_backward(self, params, optimizers, step, info):
            self.calls.append(("post", step, info[self.grad_key].grad is not None))
            return {}

    cfg = get_method("splatfacto").config
    pipeline = Pipeline(cfg.pipeline, tiny_scene, "cpu")
    model = pipeline.model
    model.strategy = rec = Recording()
    opts = Optimizers(cfg.optimizers, model.get_param_groups())
    callbacks = model.get_training_callbacks(TrainingCallbackAttributes(optimizers=opts, pipeline=pipeline))
    for where in (Loc.BEFORE_STEP,):
        for cb in callbacks:
            cb.run(where, 3)
    model.train()
    _, losses, _ = pipeline.get_train_loss_dict(3)
    sum(losses.values()).backward()
    for where in (Loc.AFTER_BACKWARD, Loc.AFTER_STEP):
        for cb in callbacks:
            cb.run(where, 3)
    assert rec.calls == [("pre", 3), ("post", 3, True)]


@pytest.mark.parametrize("make", [lambda: DefaultStrategy(DefaultStrategyConfig()), lambda: SurfelStrategy(DefaultStrategyConfig()),
                                  lambda: AnchorStrategy(ScaffoldGSModelConfig(), 0.1), lambda: MCMCStrategy(MCMCStrategyConfig())])
def test_accumulated_statistics_round_trip_through_a_checkpoint(make):
    """Every statistic a strategy combines over ranks is what its checkpoint state carries, and a fresh
    strategy loaded from it holds the same tensors (MCMC accumulates none: empty)."""
    src = make()
    for k, path in enumerate(src.reduced_stats):
        src._set_stat(path, torch.arange(4.0) + k)
    state = src.state_dict()
    assert set(state) == set(src.reduced_stats)
    dst = make()
    dst.load_state_dict(torch.load(_saved(state), weights_only=True))
    for path in src.reduced_stats:
        assert torch.equal(dst._stat(path), src._stat(path))
    dst.load_state_dict({})  # an older checkpoint: no statistics yet
    assert all(dst._stat(p) is None for p in dst.reduced_stats)


def _saved(state):
    import io

    buf = io.BytesIO()
    torch.save(state, buf)
    buf.seek(0)
    return buf
