"""The masks stage as ``ns2gs-data masks --segmenter auto`` runs it, for the motion-mask benches
(``benchmarks/validation/motion_masks_{scene,real}.py``): the capture's mask-less reference rendered at
a ``render_downscale`` (``render_views``), then ``masks_for_renders`` with the default motion route and
its second pass (the function ``auto_masks`` calls), keeping the masks without motion and those before
the second pass for the rows that compare them.

The reference is keyed on the model code (:func:`~nerf2gs_bench.code_version.model_code_hash`,
written beside it when this module trains it): one without that key, or with another, is retrained,
unless ``reuse_stale`` (then the JSON says so), and never when today's code would configure it
otherwise (the warm start of the second pass refuses those anyway).
"""

from __future__ import annotations

import copy
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional

if TYPE_CHECKING:
    from nerf2gs_plugin.masks.motion import MotionOptions

REFERENCE_STEPS = 1000
"""The benches' first reference (mask-less StreetNeRF), as ``ns2gs-data masks``' default."""
KEY_FILE = "model_code.txt"


def _config_difference(reference: Path) -> str | None:
    from nerf2gs_plugin.engine.config import read_config_doc
    from nerf2gs_plugin.engine.warm_start import config_difference
    from nerf2gs_plugin.masking.mask_reference import reference_config
    from nerf2gs_plugin.utils.config import to_plain

    ours = to_plain(reference_config(reference, reference, REFERENCE_STEPS, 1.0, False).pipeline.model)
    theirs = read_config_doc(reference / "config.yml")["config"].get("pipeline", {}).get("model", {})
    return config_difference(theirs, ours)


def ensure_keyed_reference(capture: Path, reference: Path, reuse_stale: bool = False,
                           log: Callable[[str], None] = print) -> dict:
    """``reference`` (a run folder) for ``capture``, trained afresh where it is not today's (see the
    module docstring); returns what keys it: ``{"code": hash or None, "today": hash, "stale": bool}``."""
    from nerf2gs_bench.code_version import model_code_hash
    from nerf2gs_plugin.masking.mask_reference import ensure_reference

    today = model_code_hash()
    key_file = reference / KEY_FILE
    code = key_file.read_text().strip() if key_file.is_file() else None
    if (reference / "config.yml").is_file():
        why = _config_difference(reference)
        if why or (code != today and not reuse_stale):
            log(f"{reference}: trained again ({why or f'model code {code} there, {today} here'})")
            shutil.rmtree(reference)
            code = None
    if not (reference / "config.yml").is_file():
        ensure_reference(capture, reference, REFERENCE_STEPS, progress=False, log=log)
        key_file.write_text(today + "\n")
        code = today
    return {"code": code, "today": today, "stale": code != today}


def product_masks(capture: Path, reference: Path, render_downscale: int, log: Callable[[str], None] = print,
                  motion: Optional[MotionOptions] = None) -> dict:
    """The training frames' masks of the masks stage on ``capture`` with ``reference`` (``motion``: the
    route's ``MotionOptions``, its defaults when None):
    ``{"names", "without_motion", "first_pass", "second_pass", "settled", "timings"}`` (the masks as
    :class:`~nerf2gs_plugin.masks.auto.FrameMasks` lists at the frames' full size)."""
    from nerf2gs_plugin.masking.auto_masks import at_full_size, masks_for_renders, render_views
    from nerf2gs_plugin.masks.auto import AutoOptions, masks_from_renders
    from nerf2gs_plugin.masks.maskless import maskless_view
    from nerf2gs_plugin.masks.motion import MotionOptions
    from nerf2gs_plugin.utils.parallel import cpu_seconds

    view = maskless_view(capture)
    t0, c0 = time.perf_counter(), cpu_seconds()
    renders = render_views(view, reference, ["train"], log, False, render_downscale)
    timings = {"render_seconds": round(renders.seconds, 1), "render_cpu_seconds": round(renders.cpu_seconds, 1)}
    without = masks_from_renders(renders, AutoOptions(), log=lambda s: None)
    at_full_size(renders, without)  # the masks upsampled in place, as they would be written
    first: dict = {}
    second: dict = {}
    result = masks_for_renders(view, reference, renders, AutoOptions(), log, False, motion or MotionOptions(), timings, render_downscale,
                               first_pass=lambda res: first.update(copy.deepcopy(res)),
                               before_settle=lambda res: second.update(copy.deepcopy(res)))
    timings.update(seconds=round(time.perf_counter() - t0, 1), cpu_seconds=round(cpu_seconds() - c0, 1))
    return {"names": [v["name"] for v in renders.views["train"]], "without_motion": without["train"],
            "first_pass": first.get("train", result["train"]), "second_pass": second.get("train", result["train"]),
            "settled": result["train"], "timings": timings}
