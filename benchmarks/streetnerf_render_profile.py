"""Where one StreetNeRF render spends its CPU time: each network's share and the rest.

    OMP_NUM_THREADS=1 python benchmarks/streetnerf_render_profile.py RUN [--width 480] [--views 2] [--repeats 2]

RUN is a StreetNeRF run directory or checkpoint. Training views are rendered at ``--width`` (aspect kept),
one torch thread; each network's forward and the positions' contraction (world -> grid
coordinates and radii) are timed in CPU seconds (``time.process_time``), the rest is
sample placement, contraction, proposal resampling, compositing and indexing. Also printed: the share of
fine samples that reach the colour network (weight > ``render_min_weight``) and the share of each round's
samples lying behind the point where the ray's transmittance fell below that weight (what early ray
termination could at most skip). Best of ``--repeats``.
"""

from __future__ import annotations

import argparse
import collections
import time
from pathlib import Path

import torch


def _timed(acc: collections.Counter, name: str, module: torch.nn.Module) -> None:
    forward = module.forward

    def wrapped(*args, **kwargs):
        t = time.process_time()
        out = forward(*args, **kwargs)
        acc[name] += time.process_time() - t
        return out

    module.forward = wrapped


def _timed_method(acc: collections.Counter, name: str, modules, method: str) -> None:
    for module in modules:
        fn = getattr(module, method)

        def wrapped(*args, _fn=fn, **kwargs):
            t = time.process_time()
            out = _fn(*args, **kwargs)
            acc[name] += time.process_time() - t
            return out

        setattr(module, method, wrapped)


def _behind(w: torch.Tensor, eps: float) -> float:
    return float(((1.0 - torch.cumsum(w, -1)) < eps).float().mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--views", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    from nerf2gs_plugin.runs.model import load_run_model

    torch.set_num_threads(1)
    run = load_run_model(args.run)
    m = run.model
    n = len(run.train_cameras)
    cams = [run.train_cameras[i : i + 1] for i in range(n // (2 * args.views), n, max(n // args.views, 1))][: args.views]
    cams = [c.scaled(args.width / int(c.width[0])) for c in cams]
    rays = sum(int(c.width[0]) * int(c.height[0]) for c in cams)
    acc: collections.Counter = collections.Counter()
    for i, p in enumerate(m.proposals):
        _timed(acc, f"proposal {i}: hash grid", p.encoding)
        _timed(acc, f"proposal {i}: MLP", p.mlp)
    _timed_method(acc, "proposals: contraction", m.proposals, "grid_coords")
    _timed_method(acc, "field: contraction", [m.field], "grid_coords")
    _timed(acc, "field: hash grid", m.field.encoding)
    _timed(acc, "field: density MLP", m.field.density_mlp)
    _timed(acc, "field: colour MLP", m.field.color_mlp)
    if m.sky_model is not None:
        _timed(acc, "sky", m.sky_model)
    best, parts = float("inf"), {}
    for _ in range(args.repeats):
        acc.clear()
        t = time.process_time()
        for c in cams:
            m.render_camera(c)
        total = time.process_time() - t
        if total < best:
            best, parts = total, dict(acc)
    per_view = best / len(cams)
    print(f"{len(cams)} views of {int(cams[0].width[0])}x{int(cams[0].height[0])}: {per_view:.3f} CPU s per view, "
          f"{rays / best / 1000:.1f}k rays per CPU s")
    for name, v in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"  {name:24s} {v / len(cams):.3f} s  {100 * v / best:4.0f}%")
    rest = best - sum(parts.values())
    print(f"  {'rest':24s} {rest / len(cams):.3f} s  {100 * rest / best:4.0f}%")
    eps = m.config.render_min_weight
    with torch.no_grad():
        m.eval()
        out = m._render_rays(cams[0].generate_rays(0)[:8192], None)
    print(f"fine samples with weight > {eps:g}: {float((out['weights'] > eps).float().mean()):.2f}")
    for i, (_, w) in enumerate(out["proposals"]):
        print(f"proposal {i}: samples behind transmittance < {eps:g}: {_behind(w, eps):.2f}")
    print(f"fine: samples behind transmittance < {eps:g}: {_behind(out['weights'], eps):.2f}")


if __name__ == "__main__":
    main()
