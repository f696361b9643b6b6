"""Real training pairs for the built-in enhancer, made from a reference run and the training images.

Two kinds, both with a loss mask:

* ``pose``: the reference's render at a training pose vs. that training image (transient objects
  masked out: the NeRF removes the cars the ground truth still shows);
* ``perturbed``: the reference's render from a camera raised and pitched down from a training pose
  (toward the bird's-eye views the enhancer is for) vs. the training image warped into that camera
  through the reference's rendered depth. Pixels whose warped depth disagrees with the depth the
  reference renders at the training pose (occluded there), that fall outside the training image,
  or that land on a transient object are masked out. These are real novel-view artifacts
  (stretched texture, floaters seen from a new angle) with a ground truth, which renders at the
  training poses alone do not show.

With ``condition_of`` (``--condition warped``), every pair also carries its condition: the real
training view ``condition_of[i]`` (never ``i`` itself, whose image is the target) warped into the
pair's camera through the reference's depth there, with its validity mask
(:func:`~nerf2gs_plugin.enhancer.warp.warped_reference`), as the augmentation builds it for a
bird's-eye view.

Everything is vectorised over pixels; the loops run over images.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional, Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from nerf2gs_plugin.cameras import raise_and_pitch
from nerf2gs_plugin.data.normalize import load_dataparser_transform
from nerf2gs_plugin.errors import ConfigError
from nerf2gs_plugin.enhancer.warp import clear_mask, warp_into, warped_reference
from nerf2gs_plugin.progress import make_progress

# Camera perturbation for ``perturbed`` pairs, in metres and degrees (uniform ranges).
RAISE_M = (2.0, 8.0)
PITCH_DEG = (10.0, 35.0)
SIDE_M = 1.0


@dataclass
class Pair:
    """One training pair: ``[3, H, W]`` input and target, ``[1, H, W]`` loss mask, training image index."""

    render: Tensor
    target: Tensor
    mask: Tensor
    index: int
    kind: str  # "pose" or "perturbed"
    condition: Optional[Tensor] = None  # [4, H, W]: another training view warped in, and where it is valid
    condition_index: Optional[int] = None  # the training view it was warped from


def _chw(img: Tensor) -> Tensor:
    return img.permute(2, 0, 1).contiguous().float().cpu()


def metres_per_unit(run_dir: Path) -> float:
    """Metres per world unit of a run (``dataparser_transforms.json``), 1 when unknown."""
    path = Path(run_dir) / "dataparser_transforms.json"
    if not path.is_file():
        return 1.0
    tf = load_dataparser_transform(path)
    return float(tf.metres_per_unit / tf.scale) if tf.scale > 0 else 1.0


def perturb_pose(c2w: Tensor, up: Tensor, gen: torch.Generator, metres: float) -> Tensor:
    """``[3, 4]`` camera raised by RAISE_M along ``up``, shifted sideways by up to SIDE_M and pitched down by PITCH_DEG."""
    u = lambda lo, hi: lo + (hi - lo) * float(torch.rand((), generator=gen))  # noqa: E731
    pitch = u(*PITCH_DEG)  # drawn first, as before: the pairs of a seed stay the pairs of that seed
    out = raise_and_pitch(c2w[None].float(), up.to(c2w.device).float(), u(*RAISE_M) / metres, pitch)[0]
    out[:, 3] = out[:, 3] + out[:, 0] * (u(-SIDE_M, SIDE_M) / metres)
    return out


def _loss_mask(images, i: int) -> Tensor:
    """``[1, H, W]``: 1 where the ground truth may be compared with a render (transients grown by 2 px are 0)."""
    return clear_mask(images.mask("transient", i), *images.hw(i))


def reference_pairs(refs: Sequence[Path], data: Path, indices: Sequence[int], gen: torch.Generator,
                    perturbed: bool = True, progress: bool = True,
                    condition_of: Optional[Mapping[int, int]] = None) -> list[Pair]:
    """``pose`` pairs (and ``perturbed`` ones when asked) at the training images ``indices``, from each
    reference; with ``condition_of`` (training index -> another training index), conditioned pairs."""
    from nerf2gs_plugin.runs.load import load_run

    if condition_of is not None:
        own = [i for i in indices if condition_of[i] == i]
        if own:
            raise ValueError(f"a pair's condition must come from another training view (image {own[0]} conditions on itself)")

    pairs: list[Pair] = []
    runs = [load_run(Path(r), data=data) for r in refs]
    with make_progress(progress) as bar, torch.no_grad():
        task = bar.add_task("render reference views", total=len(runs) * len(indices), stats="")
        for run in runs:
            imgs = run.pipeline.datamanager.train_images
            cams = imgs.cameras
            up = F.normalize(cams.camera_to_worlds[:, :3, 1].float().mean(0), dim=0)
            metres = metres_per_unit(run.run_dir)
            depths: dict[int, Tensor] = {}  # the reference's depth at training views (condition sources)
            for i in indices:
                cam = cams[i]
                out = run.model.render_camera(cam)
                gt, mask = _chw(imgs.image(i)), _loss_mask(imgs, i)
                pairs.append(Pair(_chw(out["rgb"]), gt, mask, i, "pose"))
                views = [(pairs[-1], cam, out)]
                if perturbed:
                    c2w = perturb_pose(cam.camera_to_worlds[0], up, gen, metres)
                    moved = dataclasses.replace(cam, camera_to_worlds=c2w[None])
                    novel = run.model.render_camera(moved)
                    target, valid = warp_into(moved, novel["depth"], cam.camera_to_worlds[0], float(cam.fx[0]), float(cam.fy[0]),
                                              float(cam.cx[0]), float(cam.cy[0]), _chw(out["depth"]), gt, mask)
                    pairs.append(Pair(_chw(novel["rgb"]), target, valid, i, "perturbed"))
                    views.append((pairs[-1], moved, novel))
                if condition_of is not None:
                    depths.setdefault(i, out.get("depth"))
                    for q, camera, seen in views:
                        q.condition_index = int(condition_of[i])
                        q.condition = _condition(run, imgs, depths, q.condition_index, camera, seen)
                bar.update(task, advance=1, stats=f"{run.config.method_name} step {run.step}")
    return pairs


def _condition(run, imgs, depths: dict, j: int, camera, seen: dict[str, Tensor]) -> Tensor:
    """``[4, H, W]``: training view ``j`` warped into ``camera`` through the reference's depth ``seen["depth"]`` there."""
    if j not in depths:  # a condition source not (yet) rendered: its depth is rendered once
        depths[j] = run.model.render_camera(imgs.cameras[j]).get("depth")
    if depths[j] is None or "depth" not in seen:
        raise ConfigError(f"--condition warped needs a reference that renders depth ({run.config.method_name} does not)")
    along = getattr(run.model, "depth_along", "ray")
    ref = warped_reference(camera, seen["depth"].detach().cpu(), imgs.cameras[j], depths[j].detach().cpu(), imgs.image(j).cpu(),
                           _loss_mask(imgs, j), along)
    return ref.permute(2, 0, 1).contiguous()


def split_indices(n: int, holdout_every: int, max_train: Optional[int], gen: torch.Generator) -> tuple[list[int], list[int]]:
    """(pair indices, held-out validation indices): every ``holdout_every``-th image is held out (0 = none)."""
    held = list(range(0, n, holdout_every)) if holdout_every > 0 and n > 1 else []
    rest = [i for i in range(n) if i not in set(held)]
    if max_train is not None and len(rest) > max_train:
        rest = sorted(rest[k] for k in torch.randperm(len(rest), generator=gen)[:max_train].tolist())
    return rest, held
