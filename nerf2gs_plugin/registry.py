"""Method registry: built-in methods in code, third-party ones from the ``nerf2gs.methods``
entry-point group. A plugin that fails to load is reported by name and skipped."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

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
    # the original step counts and schedules, for a GPU (`ns2gs-train splatfacto-paper ...`)
    "streetnerf-paper": "nerf2gs_plugin.methods.streetnerf.config:streetnerf_paper_method",
    "splatfacto-paper": "nerf2gs_plugin.methods.splatfacto.config:splatfacto_paper_method",
    "scaffold-gs-paper": "nerf2gs_plugin.methods.scaffold_gs.config:scaffold_gs_paper_method",
    "2dgs-paper": "nerf2gs_plugin.methods.two_dgs.config:two_dgs_paper_method",
}


@dataclass
class MethodSpecification:
    """A method: its default config (a tyro-parsable TrainerConfig) and a one-line description."""

    config: TrainerConfig
    description: str

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
