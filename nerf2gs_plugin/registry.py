"""Method registry: built-in methods in code, third-party ones from the ``nerf2gs.methods``
entry-point group. A plugin that fails to load is reported by name and skipped."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING, Callable

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.utils.plugins import load_entry_points, load_ref

if TYPE_CHECKING:  # an annotation only: importing the registry loads neither the engine nor a method
    from nerf2gs_plugin.engine.trainer_config import TrainerConfig

ENTRY_POINT_GROUP = "nerf2gs.methods"

# name -> "module:attribute" of a MethodSpecification; imported lazily so one broken method
# (e.g. a missing optional dependency) never hides the others.
BUILTIN_METHODS: dict[str, str] = {
    "streetnerf": "nerf2gs_plugin.methods.streetnerf.config:streetnerf_method",
    "splatfacto": "nerf2gs_plugin.methods.splatfacto.config:splatfacto_method",
    "scaffold-gs": "nerf2gs_plugin.methods.scaffold_gs.config:scaffold_gs_method",
    "2dgs": "nerf2gs_plugin.methods.two_dgs.config:two_dgs_method",
}
# older names of a method at a preset (``ns2gs-train splatfacto-paper`` = ``splatfacto --preset paper``)
ALIASES: dict[str, tuple[str, str]] = {f"{name}-paper": (name, "paper") for name in BUILTIN_METHODS}


@dataclass
class Preset:
    """A scale of a method (``--preset NAME``): its default config turned into the preset's."""

    apply: Callable[[TrainerConfig], TrainerConfig]
    description: str


@dataclass
class MethodSpecification:
    """A method: its default config (a tyro-parsable TrainerConfig), a one-line description, and its
    presets (e.g. ``paper``: the original step counts and schedules, for a GPU)."""

    config: TrainerConfig
    description: str
    presets: dict[str, Preset] = field(default_factory=dict)

    def preset(self, name: str) -> MethodSpecification:
        """This method at preset ``name`` (its config and description; ConfigError for an unknown one)."""
        if name not in self.presets:
            known = ", ".join(sorted(self.presets)) or "none"
            raise ConfigError(f"unknown preset '{name}' for method '{self.config.method_name}'; its presets: {known}",
                              "--preset")
        chosen = self.presets[name]
        return MethodSpecification(chosen.apply(self.config), chosen.description)

    def with_steps(self, steps: int) -> TrainerConfig:
        """The config with ``steps`` iterations and every schedule marked in its dataclasses
        (``nerf2gs_plugin.utils.schedule``) rescaled to them: densification, SH degree, loss
        start steps, learning-rate decay. A third-party method's marked fields are rescaled too."""
        from nerf2gs_plugin.utils.schedule import with_steps

        return with_steps(self.config, steps)


@dataclass
class Discovery:
    methods: dict[str, MethodSpecification]
    failures: dict[str, str]  # name -> one-line reason


@lru_cache(maxsize=1)
def discover_methods() -> Discovery:
    methods: dict[str, MethodSpecification] = {}
    failures: dict[str, str] = {}
    for name, ref in BUILTIN_METHODS.items():
        try:
            spec = load_ref(ref)
        except ModuleNotFoundError as e:
            if e.name and e.name.startswith("nerf2gs_plugin.methods"):
                continue  # not built yet in this tree: not a failure
            failures[name] = f"{type(e).__name__}: {e}"
            continue
        except KeyboardInterrupt:
            raise
        except BaseException as e:  # noqa: BLE001
            failures[name] = f"{type(e).__name__}: {e}"
            continue
        methods[name] = spec
    for alias, (name, preset) in ALIASES.items():
        if name in methods:
            methods[alias] = methods[name].preset(preset)
    plugins, plugin_failures = load_entry_points(ENTRY_POINT_GROUP, MethodSpecification, methods)
    return Discovery({**methods, **plugins}, {**failures, **plugin_failures})


def report_failures(discovery: Discovery, file=None) -> None:
    for name, reason in discovery.failures.items():
        print(f"warning: method plugin '{name}' failed to load and is skipped ({reason})", file=file or sys.stderr)


def get_method(name: str) -> MethodSpecification:
    disc = discover_methods()
    if name not in disc.methods:
        known = ", ".join(sorted(disc.methods)) or "none"
        extra = f" (it failed to load: {disc.failures[name]})" if name in disc.failures else ""
        raise ConfigError(f"unknown method '{name}'{extra}; known methods: {known}")
    return disc.methods[name]
