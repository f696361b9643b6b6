"""with_steps is one generic function: it rescales exactly the fields marked ``scheduled`` in any
registered method's config tree (plugins included) and nothing else."""

import dataclasses
from dataclasses import dataclass, field

import pytest

from nerf2gs_plugin.registry import discover_methods
from nerf2gs_plugin.utils.schedule import SCHEDULE_KEY, scheduled, with_steps


def _walk(value, path=""):
    """(path, field, owner) of every dataclass field in a config tree (dicts of configs included)."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _walk(v, f"{path}{k}.")
        return
    if not dataclasses.is_dataclass(value) or isinstance(value, type):
        return
    for f in dataclasses.fields(value):
        yield f"{path}{f.name}", f, value
        yield from _walk(getattr(value, f.name), f"{path}{f.name}.")


def _get(config, path):
    for part in path.split("."):
        config = config[part] if isinstance(config, dict) else getattr(config, part)
    return config


@pytest.mark.parametrize("name", sorted(discover_methods().methods))
def test_with_steps_rescales_marked_fields_of_every_method(name):
    spec = discover_methods().methods[name]
    cfg = spec.config
    steps = max(cfg.max_num_iterations // 3, 1)
    ratio = steps / cfg.max_num_iterations
    quick = spec.with_steps(steps)
    marked = 0
    for path, f, owner in _walk(cfg):
        before, after = getattr(owner, f.name), _get(quick, path)
        kind = f.metadata.get(SCHEDULE_KEY)
        if kind is None:
            if not (dataclasses.is_dataclass(before) or isinstance(before, dict)):
                assert after == before, path
            continue
        marked += 1
        expected = {"total": steps, "step": max(1, round(before * ratio)), "interval": max(20, min(before, round(before * ratio))),
                    "cap": min(before, steps),
                    "horizon": steps if getattr(owner, f.metadata.get("only_if", f.name)) is not None else before}[kind]
        assert after == expected, (path, kind, before, after)
    assert marked >= 2  # at least the run length and the save interval
    assert quick.max_num_iterations == steps


def test_splatting_methods_mark_their_schedules():
    methods = discover_methods().methods
    m = methods["splatfacto"].with_steps(750).pipeline.model
    assert (m.sh_degree_interval, m.strategy.stop_split_at, m.strategy.refine_every, m.mcmc.refine_stop_iter) == (75, 375, 25, 625)
    t = methods["2dgs"].with_steps(1500).pipeline.model
    assert (t.dist_start, t.normal_start) == (150, 350)
    s = methods["scaffold-gs"].with_steps(1500).pipeline.model
    assert (s.start_stat, s.update_from, s.update_until, s.update_interval) == (25, 75, 750, 50)


def test_third_party_config_is_rescaled_by_its_marks():
    @dataclass
    class Inner:
        start: int = scheduled(400)
        every: int = scheduled(100, "interval")
        weight: float = 0.5

    @dataclass
    class Outer:
        max_num_iterations: int = scheduled(1000, "total")
        steps_per_save: int = scheduled(500, "cap")
        inner: Inner = field(default_factory=Inner)
        groups: dict = field(default_factory=lambda: {"a": Inner(start=10)})

    out = with_steps(Outer(), 100)
    assert (out.max_num_iterations, out.steps_per_save, out.inner.start, out.inner.every, out.inner.weight) == (100, 100, 40, 20, 0.5)
    assert out.groups["a"].start == 1
    with pytest.raises(ValueError, match="run length"):
        with_steps(Inner(), 10)
    with pytest.raises(ValueError, match="unknown schedule kind"):
        scheduled(1, "sometimes")
