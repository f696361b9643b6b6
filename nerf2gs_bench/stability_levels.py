"""The stability bench's stresses: each a ladder of levels, mild -> harsh, walked until it breaks.

A level is what changes in the run against the unstressed seed run: a perturbed dataset copy
(:class:`~nerf2gs_bench.perturb.Perturbation`), more transients (the synthetic street only)
or, for the augmented pipeline, a shorter reference. In "target + NeRF views" the reference is
trained on the same stressed data that the target trains on (the reference's own stress), so
every data stress also stresses the NeRF views.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from nerf2gs_plugin.errors import ConfigError
from nerf2gs_bench.perturb import Perturbation

NOISE_SEED = 7  # the pose-noise / mask-drop / exposure draws (the committed mild pose-noise run used 7)
AUGMENTED_SUFFIX = "+nerf"  # --methods splatfacto+nerf: Splatfacto trained with StreetNeRF's views
AUGMENTED_LABEL = " + NeRF views"
REFERENCE_METHOD = "streetnerf"


@dataclass(frozen=True)
class Level:
    """One rung of a stress ladder."""

    label: str
    perturbation: Optional[Perturbation] = None
    transients_factor: int = 1
    reference_steps_fraction: float = 1.0
    """Augmented pipeline only: the reference trains this fraction of its steps."""
    case_name: str = ""
    """The run's name in the tables when not "<stress> <label>" (the one-level bench's names, kept)."""

    def variant(self, stress: str) -> str:
        return self.case_name or f"{stress} {self.label}"


def _pose(deg: float, cm: float) -> Level:
    return Level(f"{deg:g}deg/{cm:g}cm", Perturbation(rotation_deg=deg, translation_m=cm / 100, seed=NOISE_SEED))


STRESS_LEVELS: dict[str, tuple[Level, ...]] = {
    "pose noise": tuple(_pose(d, c) for d, c in ((0.25, 2.5), (0.5, 5), (1, 10), (2, 20), (4, 40))),
    "views kept": tuple(Level(f"{100 // k}%", Perturbation(keep_every=k)) for k in (2, 4, 8)),
    "transients": tuple(Level(f"{f}x", transients_factor=f) for f in (2, 4, 8)),
    # one kind of mask error per ladder, so each is walked to its own breaking point (a mixed ladder
    # stopped at the first kind that failed and never reached the harsher levels of the others)
    "mask erosion": tuple(Level(f"{px}px", Perturbation(mask_erode_px=px)) for px in (2, 6, 12)),
    "mask dilation": tuple(Level(f"{px}px", Perturbation(mask_dilate_px=px)) for px in (2, 6, 12)),
    "mask drop": (Level("50%", Perturbation(mask_drop_fraction=0.5, seed=NOISE_SEED)),
                  Level("100%", Perturbation(drop_masks=True), case_name="no masks")),
    "exposure": tuple(Level(f"+-{s:g} stop", Perturbation(exposure_spread=s, seed=NOISE_SEED)) for s in (0.25, 0.5, 1.0, 2.0)),
    "init": (Level("random", Perturbation(drop_points=True), case_name="random init"),),
    "reference steps": tuple(Level(f"{round(f * 100):g}%", reference_steps_fraction=f) for f in (0.5, 0.25, 0.12, 0.06)),
}
AUGMENTED_ONLY = ("reference steps",)


@dataclass(frozen=True)
class BenchMethod:
    """A method of the bench: a registered method, or a target trained with the reference's views."""

    method: str
    augmented: bool = False

    @property
    def label(self) -> str:
        return self.method + (AUGMENTED_LABEL if self.augmented else "")


def parse_method(name: str) -> BenchMethod:
    """``splatfacto``, ``splatfacto+nerf`` or ``splatfacto + NeRF views`` -> :class:`BenchMethod`
    (an unknown method or an augmented reference is a ConfigError)."""
    from nerf2gs_plugin.registry import get_method

    raw = name.strip()
    augmented = raw.lower().endswith(AUGMENTED_SUFFIX) or raw.endswith(AUGMENTED_LABEL)
    base = raw[: -len(AUGMENTED_SUFFIX)] if raw.lower().endswith(AUGMENTED_SUFFIX) else raw.removesuffix(AUGMENTED_LABEL)
    base = base.strip()
    get_method(base)  # unknown -> ConfigError naming the known ones
    if augmented and base == REFERENCE_METHOD:
        raise ConfigError(f"'{name}': the reference cannot be trained on its own views (use a target: splatfacto+nerf)")
    return BenchMethod(base, augmented)


def stresses_for(method: BenchMethod, names: Optional[tuple[str, ...]] = None) -> list[str]:
    """The stresses a method is swept over (all by default; reference steps only when augmented)."""
    names = tuple(names or STRESS_LEVELS)
    unknown = [n for n in names if n not in STRESS_LEVELS]
    if unknown:
        raise ConfigError(f"unknown stress {', '.join(repr(n) for n in unknown)}; known: {', '.join(STRESS_LEVELS)}")
    return [n for n in names if method.augmented or n not in AUGMENTED_ONLY]
