"""Optimizers: the fused Adam update is the per-tensor one, to float rounding."""

import torch

from nerf2gs_plugin.engine.optimizers import OptimizerConfig, Optimizers


def _params(seed: int) -> dict[str, list[torch.nn.Parameter]]:
    g = torch.Generator().manual_seed(seed)
    shapes = {"fields": [(4, 512, 2), (64, 24), (64,), (3, 64), (3,)], "other": [(100, 3)]}
    return {k: [torch.nn.Parameter(torch.randn(s, generator=g) * 1e-2) for s in v] for k, v in shapes.items()}


def test_fused_adam_is_the_per_tensor_update():
    configs = {"fields": OptimizerConfig(lr=1e-2, eps=1e-15, lr_final=1e-3, max_steps=20),
               "other": OptimizerConfig(lr=5e-3, eps=1e-15, weight_decay=1e-4)}
    ours, ref = _params(0), _params(0)
    opts = Optimizers(configs, ours)
    assert all(o.defaults["fused"] for o in opts.optimizers.values())
    reference = {k: torch.optim.Adam(v, lr=configs[k].lr, eps=configs[k].eps, weight_decay=configs[k].weight_decay, foreach=False)
                 for k, v in ref.items()}
    g = torch.Generator().manual_seed(1)
    for step in range(12):
        if step == 6:  # a densification's swap of a parameter (Splatfacto): kept rows and new ones
            keep = torch.arange(100) % 3 != 0
            for params, replace in ((ours, lambda p: opts.replace_param("other", p, keep, 5)), (ref, None)):
                new = torch.nn.Parameter(torch.cat([params["other"][0].detach()[keep], torch.zeros(5, 3)]))
                if replace:
                    replace(new)
                else:
                    old = reference["other"].param_groups[0]["params"][0]
                    state = reference["other"].state.pop(old)
                    for key in ("exp_avg", "exp_avg_sq"):
                        state[key] = torch.cat([state[key][keep], torch.zeros(5, 3)])
                    reference["other"].param_groups[0]["params"][0] = new
                    reference["other"].state[new] = state
                params["other"][0] = new
        for name in ours:
            for i, (a, b) in enumerate(zip(ours[name], ref[name])):
                grad = None if (step % 4 == 1 and i == 1) else torch.randn(a.shape, generator=g)  # sometimes no gradient
                a.grad, b.grad = grad, None if grad is None else grad.clone()
        opts.step(step)
        for name, opt in reference.items():
            for group in opt.param_groups:
                group["lr"] = configs[name].lr_at(step)
            opt.step()
    for name in ours:
        for a, b in zip(ours[name], ref[name]):
            assert a.shape == b.shape and torch.allclose(a, b, rtol=1e-5, atol=1e-7)  # one pass: other roundings
    assert not torch.equal(ours["fields"][0], _params(0)["fields"][0])  # it did train
