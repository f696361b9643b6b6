"""The ``--augment.*`` flags: plain values that the trainer's config holds. They sit with the
trainer's config, below the augmentation (``nerf2gs_plugin.augment``) that reads them, so that no
import runs up from the engine; ``nerf2gs_plugin.augment.config`` names them in the augmentation's room."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, Optional

import tyro

from nerf2gs_plugin.errors import ConfigError


@dataclass
class LaneShiftConfig:
    """The lane-shift view family: the drive re-driven sideways."""

    offsets: tuple[float, ...] = (-3.0, 3.0)
    """Metres along the ground plane's lateral axis (positive: to the right of the input camera's
    heading); one view per input pose and offset (+-3 m: the best lane views of those tried on the
    validation views of two streets, benchmarks/results/lane_shift_sweep.md)."""
    look_ahead: float = 0.0
    """Metres: > 0 turns each shifted camera (yaw about the up axis) toward the point this far ahead
    on its input camera's line of travel (0: the input's own heading)."""
    every_n: int = 1
    """Use every n-th input pose."""
    share: Optional[float] = 0.05
    """Probability that a training sample is one of this family's views (None: its views' share of
    them and the input views, out of the input views' share; augment/shares.py). 0.05 with each family's
    own seed points kept the views from above within 0.2 dB of the bird's-eye views alone on the validation
    views of two streets at the registered steps (benchmarks/results/lane_levers_default.md)."""


@dataclass
class RaiseConfig:
    """The raise view family: the input views raised without pitch."""

    heights: tuple[float, ...] = (2.0,)
    """Metres above each input view along the scene's up vector; one view per input pose and height."""
    every_n: int = 1
    """Use every n-th input pose."""
    share: Optional[float] = None
    """Probability that a training sample is one of this family's views (None: its views' share of
    them and the input views, out of the input views' share; augment/shares.py)."""


@dataclass
class PosesFileConfig:
    """The poses view family: views at poses the user gives."""

    file: Optional[Path] = None
    """A JSON file: {"camera_to_worlds": [a 3x4 or 4x4 matrix per view]} (or a nerfstudio camera_path.json:
    its camera_path[].camera_to_world), OpenGL axes, in the run's normalised
    world frame (the frame of the cache manifest's saved poses); each view takes the intrinsics of
    the input camera nearest it."""
    share: Optional[float] = None
    """Probability that a training sample is one of this family's views (None: its views' share of
    them and the input views, out of the input views' share; augment/shares.py)."""


FAMILY_FIELDS = {"lane-shift": "lane_shift", "raise": "raise_", "poses": "poses"}
"""The built-in view families with parameters -> their AugmentConfig field."""


@dataclass
class AugmentConfig:
    """The --augment.* flags; used only with --augment-from."""

    composites: bool = True
    """Replace transient-mask pixels of input views by the reference render."""
    dilate_px: int = 2
    """Grow transient masks by this many pixels before compositing."""
    feather_px: int = 0
    """Soften the composite seam over this many pixels (0 = hard mask)."""
    composite_loss: Literal["paint", "either"] = "paint"
    """paint: a composite's painted pixels are the target. either (image methods: Splatfacto, Scaffold-GS, 2DGS;
    a ray-sampled one refuses it): each pixel is learnt as painted or as photographed, whichever the render is nearer (see composite-loss-margin): a false alarm of the
    masks on a static surface that the other views show keeps its photo; a mover they contradict gives way to the paint."""
    composite_loss_margin: float = 0.1
    """either: the photo is the target unless the render is nearer the paint by more than this (mean absolute
    RGB in [0, 1]): early in training a render is as blurry as the paint, and would take it over the photo."""
    extra_views: bool = True
    """Add the additional views (of every family in views) rendered by the reference."""
    views: tuple[str, ...] = ("birds-eye",)
    """View families that make the additional views from the input poses (augment/views.py): birds-eye
    (the --augment.delta-h/theta-pitch/... fields below), lane-shift, raise, poses; their parameters
    under their names (--augment.lane-shift.offsets ...). One cache entry and manifest; each family its
    own share of the training samples (--augment.lane-shift.share ...)."""
    lane_shift: LaneShiftConfig = field(default_factory=LaneShiftConfig)
    raise_: Annotated[RaiseConfig, tyro.conf.arg(name="raise")] = field(default_factory=RaiseConfig)
    poses: PosesFileConfig = field(default_factory=PosesFileConfig)
    delta_h: float = 10.0
    """Height of the additional views above the input views, in metres."""
    theta_pitch: float = 30.0
    """Downward pitch of the additional views, in degrees."""
    delta_h_spread: float = 0.0
    """Each additional view's height drawn uniformly in delta-h +- this (metres; one draw per view, fixed
    seed): a spread of heights instead of one ring of cameras (0: all at delta-h, the paper's views)."""
    theta_pitch_spread: float = 0.0
    """Each additional view's pitch drawn uniformly in theta-pitch +- this (degrees; 0: all at theta-pitch)."""
    pitch_mode: Literal["absolute", "relative"] = "absolute"
    """absolute: theta-pitch below the horizon of the ground plane (the input's tilt and roll removed);
    relative: theta-pitch added to each input camera's own tilt (the paper's Fig. 3 with level cameras)."""
    min_coverage: float = 0.5
    """A bird's-eye render whose fraction of pixels with accumulation > 0.5 is below this is dropped (warned)."""
    every_n: int = 1
    """Use every n-th input pose for an additional view."""
    view_downscale: int = 2
    """The additional views (every family's; not the composites, which are input views) are rendered and
    trained at 1/this of the input views' width and height (intrinsics scaled): their renders cost about
    1/this^2, a step on one less (1: the input views' size). Half size pays for the step factor's longer run."""
    step_factor: float = 1.4
    """The target trains this many times its configured steps, its whole schedule rescaled (1: as configured).
    The additional views take training samples from the input views, which then lose street-level detail; at
    view-downscale 2 the longer run gives those samples back in about the time the full-size views took."""
    birds_eye_share: Optional[float] = None
    """Probability that a training sample is a bird's-eye view (None: their share of them and the input
    views, the paper's draw of one image among all, at most augment/shares.DEFAULT_SHARE_CAP = 0.35: at half
    the samples street level pays for them; docs/augmentation.md "Street level"); each family has its own
    (--augment.lane-shift.share ...), so adding a family takes samples from the input views only (augment/shares.py)."""
    extra_prob: Optional[float] = None
    """Probability that a training sample comes from any additional view (None: the families' shares
    added up); when set, split between the families in proportion to their shares."""
    extra_weight: float = 1.0
    """Loss weight of additional-view samples."""
    enhancer: str = "none"
    """none | builtin | builtin:PATH | onnx:PATH: image enhancement of the additional views."""
    use_cache: bool = True
    """Reuse the reference's cached renders when their manifest matches (False: render again)."""
    confidence: Literal["none", "visibility", "consistency", "unseen", "footprint"] = "none"
    """Per-pixel loss weight of the reference's pixels. none: all 1; visibility: how many training views
    observed the surface the pixel shows (depth-consistent, not sky/transient there), reaching 1 at
    confidence-full-views, times the render's accumulation; consistency: each of those observations
    weighted by how well the reference's colour agrees with that real image; unseen: the opposite, for the
    additional views only: 1 where no training view observed the surface, falling to
    confidence-seen-weight at confidence-full-views observations (composites keep weight 1); footprint: for the
    additional views only, how much finer the view resolves the surface than the finest input view that observed
    it: 0 where an input view sees it at least as finely, 1 from confidence-footprint-ratio times finer and where
    none observed it (composites keep weight 1) (augment/confidence.py)."""
    confidence_full_views: int = 3
    """visibility: observations at which a pixel's confidence reaches 1."""
    confidence_depth_tol: float = 0.05
    """visibility, consistency: a training view observes a point when their depths agree within this fraction."""
    confidence_color_tol: float = 0.1
    """consistency: mean absolute RGB difference at which an observation counts exp(-1)."""
    confidence_seen_weight: float = 0.0
    """unseen: the loss weight of an additional view's pixel that confidence-full-views training views observed."""
    confidence_footprint_ratio: float = 2.0
    """footprint: how many times finer than the finest observing input view an additional view must resolve a
    surface for its pixel to weigh 1 (a smooth ramp from 0 at 1x; must be > 1)."""
    appearance: Literal["mean", "nearest"] = "mean"
    """How a reference with an appearance model (StreetNeRF's per-photo colour transforms) colours what
    it renders: mean: every view in the mean of the photos' transforms; nearest: each view in the
    transform of the training photo nearest it (an input view its own, a view from above the photo it
    was raised from), so the target sees the colours of the photos around each view."""
    seed_points: float = 1.0
    """The target also starts from points of the reference's depth in the additional views, one per voxel
    that none of the capture's sparse points is in (augment/seeds.py), at most this many times the sparse
    points (at least 1000): a splatting target only grows primitives by splitting those it has, so without
    them the road seen from above stays a hole (0: off)."""
    seed_points_per_family: bool = True
    """Each view family's seed points on their own grid, with their own budget of --augment.seed-points (in the
    order of --augment.views, none where an earlier family put one): one grid for all of them coarsens
    where the views from above see the road once the lane views see the street's sides too."""
    real_only_from: float = 0.9
    """Fraction of the run after which only the input views (composites) are sampled: 0.9 gives the last
    10% of the steps to the target's own street evidence (1.0: the additional views to the end; 0.9 was
    chosen on validation views of two streets and a real capture: benchmarks/results/augment_variants.md)."""
    extra_decay: bool = False
    """The additional views' share of the training samples falls linearly from its full value at the
    first step to 0 at real-only-from (the end of the run when that is 1.0): the views from above still
    shape the model while it densifies, and the input views get the samples they lose in a run of fixed
    length (on average half of the views from above's share returns to them)."""
    extra_decay_floor: float = 0.0
    """With --augment.extra-decay: the share falls to this fraction of its full value instead of to 0
    (0.5: a quarter of the views from above's share returns to the input views;
    benchmarks/results/street_level_decay_floor.md)."""
    drop_outside_box: bool = False
    """Zero the loss weight of the additional views' pixels whose reference surface lies outside the scene
    box (the far background a NeRF contracts) or that show sky (accumulation < 0.5): the target learns from
    above only the scene inside the box, and fits nothing in the air that street views would then see in
    front of their sky and far facades (augment/confidence.py:inside_box_weight)."""
    reference_sky: bool = False
    """Join the reference's sky at each input view (its accumulation < 0.5 above the horizon, rendered at a
    quarter of the resolution, cached) to the input views' sky masks, so the model's sky alpha loss
    (--pipeline.model.sky-alpha-weight) clears what the target fitted from above in front of the street
    views' sky wherever the reference sees sky, not only where the masks do (augment/reference_sky.py)."""


def share_flag(family: str) -> str:
    return "--augment.birds-eye-share" if family == "birds-eye" else f"--augment.{family}.share"


def given_share(augment: Any, family: str) -> Optional[float]:
    """The share ``augment`` sets for ``family`` (None: the default rule; a plugin family without a field: None)."""
    if family == "birds-eye":
        return getattr(augment, "birds_eye_share", None)
    attr = FAMILY_FIELDS.get(family)
    return getattr(getattr(augment, attr, None), "share", None) if attr else None


def check_given_shares(augment: Any) -> None:
    """Each share given in [0, 1) and together below 1 (the input views keep some samples); a
    :class:`ConfigError` naming the flag otherwise."""
    total = 0.0
    for family in augment.views:
        s = given_share(augment, family)
        if s is None:
            continue
        if not 0.0 <= s < 1.0:
            raise ConfigError(f"must be in [0, 1), got {s}", share_flag(family))
        total += s
    if total >= 1.0:
        raise ConfigError(f"the view families' shares add up to {total:g}: the input views need some samples",
                          " ".join(share_flag(f) for f in augment.views if given_share(augment, f) is not None))
