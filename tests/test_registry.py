import dataclasses
import sys
import textwrap

import pytest

from nerf2gs_plugin import registry
from nerf2gs_plugin.errors import ConfigError


def test_example_plugin_is_discovered():
    disc = registry.discover_methods()
    assert "voxel-grid" in disc.methods
    spec = registry.get_method("voxel-grid")
    assert spec.config.method_name == "voxel-grid"


def test_unknown_method_lists_known_ones():
    with pytest.raises(ConfigError) as e:
        registry.get_method("no-such-method")
    assert "unknown method 'no-such-method'" in str(e.value) and "voxel-grid" in str(e.value)


def test_broken_plugin_is_reported_and_isolated(tmp_path, monkeypatch, capsys):
    dist = tmp_path / "broken_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[nerf2gs.methods]\nbroken-method = broken_plugin_mod:spec\n")
    (tmp_path / "broken_plugin_mod.py").write_text(textwrap.dedent("""
        import this_module_does_not_exist_anywhere
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.discover_methods.cache_clear()
    try:
        disc = registry.discover_methods()
        assert "broken-method" in disc.failures and "this_module_does_not_exist_anywhere" in disc.failures["broken-method"]
        assert "voxel-grid" in disc.methods  # the others still load
        registry.report_failures(disc, file=sys.stderr)
        assert "method plugin 'broken-method' failed to load" in capsys.readouterr().err
        with pytest.raises(ConfigError, match="failed to load"):
            registry.get_method("broken-method")
    finally:
        registry.discover_methods.cache_clear()


@pytest.mark.parametrize("name", ["streetnerf", "splatfacto", "scaffold-gs", "2dgs"])
def test_builtin_methods_have_cpu_and_paper_scale(name):
    cpu = registry.get_method(name).config
    paper = registry.get_method(f"{name}-paper").config
    # the paper variant trains the same method (its checkpoints load as `name`), far longer
    assert paper.method_name == cpu.method_name == name
    assert paper.max_num_iterations >= 25000 > cpu.max_num_iterations


def test_registry_imports_no_layer_at_import_time():
    """The registry needs TrainerConfig only for type checking: importing it loads neither the engine
    nor a method, and the trainer imports no run loader (which imports the registry)."""
    import subprocess
    import sys

    code = ("import sys, nerf2gs_plugin.registry as r, nerf2gs_plugin.engine.trainer as t; "
            "print(sorted(m for m in sys.modules if m.startswith('nerf2gs_plugin.engine')))")
    out = subprocess.run([sys.executable, "-c", "import sys; import nerf2gs_plugin.registry; "
                          "print(sorted(m for m in sys.modules if m.startswith('nerf2gs_plugin.') and m != 'nerf2gs_plugin.registry'))"],
                         capture_output=True, text=True, timeout=120, check=True).stdout
    assert "engine" not in out and "methods" not in out, out
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True).stdout
    assert "nerf2gs_plugin.runs.load" not in out, out


def test_plugin_calling_sys_exit_at_import_is_isolated(tmp_path, monkeypatch):
    """A plugin that calls sys.exit() at import must not end every ns2gs-train with exit 1."""
    dist = tmp_path / "exiting_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: exiting-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[nerf2gs.methods]\nexiting-method = exiting_plugin_mod:spec\n")
    (tmp_path / "exiting_plugin_mod.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.discover_methods.cache_clear()
    try:
        disc = registry.discover_methods()
        assert "exiting-method" in disc.failures and "SystemExit" in disc.failures["exiting-method"]
        assert "voxel-grid" in disc.methods and "splatfacto" in disc.methods
    finally:
        registry.discover_methods.cache_clear()
        sys.modules.pop("exiting_plugin_mod", None)


@pytest.mark.parametrize("name", ["streetnerf", "splatfacto", "scaffold-gs", "2dgs"])
def test_paper_preset_and_the_old_name_resolve_to_one_config(name, tmp_path):
    """``<name> --preset paper`` is what ``<name>-paper`` was; the old name stays an alias of it."""
    from nerf2gs_plugin.cli.train import parse_args
    from nerf2gs_plugin.utils.config import to_plain

    spec = registry.get_method(name)
    assert registry.ALIASES[f"{name}-paper"] == (name, "paper")
    assert to_plain(registry.get_method(f"{name}-paper").config) == to_plain(spec.preset("paper").config)
    assert to_plain(spec.preset("paper").config) != to_plain(spec.config)
    flags = ["--data", str(tmp_path), "--max-num-iterations", "7"]
    by_preset, _ = parse_args([name, "--preset", "paper", *flags])
    by_alias, _ = parse_args([f"{name}-paper", *flags])
    by_equals, _ = parse_args([name, *flags, "--preset=paper"])
    assert to_plain(by_preset) == to_plain(by_alias) == to_plain(by_equals)
    assert by_preset.max_num_iterations == 7 and by_preset.method_name == name  # the flags apply on top of the preset
    plain, _ = parse_args([name, *flags])
    assert to_plain(plain) == to_plain(dataclasses.replace(spec.config, data=tmp_path, max_num_iterations=7))
    with pytest.raises(ConfigError, match="unknown preset 'gpu'.*paper"):
        parse_args([name, "--preset", "gpu", *flags])


def test_steps_rescales_the_whole_schedule_and_flags_apply_on_top(tmp_path):
    """``--steps N`` is the method at N steps with its schedule rescaled (as a bench's ``with_steps``);
    ``--max-num-iterations`` after it still wins, a bad N is refused naming the flag."""
    from nerf2gs_plugin.cli.train import parse_args
    from nerf2gs_plugin.utils.config import to_plain

    spec = registry.get_method("splatfacto")
    cfg, _ = parse_args(["splatfacto", "--steps", "4200", "--data", str(tmp_path)])
    assert to_plain(cfg) == to_plain(dataclasses.replace(spec.with_steps(4200), data=tmp_path))
    strategy = cfg.pipeline.model.strategy
    assert cfg.max_num_iterations == 4200 and strategy.stop_split_at == round(spec.config.pipeline.model.strategy.stop_split_at * 1.4)
    paper, _ = parse_args(["splatfacto", "--preset", "paper", "--steps=600", "--data", str(tmp_path), "--max-num-iterations", "500"])
    assert paper.max_num_iterations == 500
    assert to_plain(paper.pipeline) == to_plain(spec.preset("paper").with_steps(600).pipeline)  # preset first, then rescaled
    for bad in ("0", "-3", "many"):
        with pytest.raises(ConfigError, match="--steps.*positive whole number"):
            parse_args(["splatfacto", "--steps", bad, "--data", str(tmp_path)])
