"""``make demo`` (``ns2gs-bench demo``): the quick paper table for a first-time user.

Everything it writes is under ``outputs/demo/`` (the committed ``benchmarks/results/quick.*`` are
regenerated only by ``ns2gs-bench quick``): the runs (``outputs/demo/runs/``, kept and reused like a
bench's), one readable link per run named for what it is (``outputs/demo/streetnerf``,
``outputs/demo/splatfacto``, ``outputs/demo/splatfacto+nerf-views``), the table, charts and
renders. It ends by printing where the runs are and the exact next commands.
"""

from __future__ import annotations

import os
import re
import shlex
from pathlib import Path

DEMO_ROOT = Path("outputs/demo")


def readable_name(label: str) -> str:
    """A bench label as a folder name: ``"splatfacto + NeRF views"`` -> ``"splatfacto+nerf-views"``."""
    name = re.sub(r"\s*\+\s*", "+", label.strip().lower())
    return re.sub(r"[^a-z0-9+._-]+", "-", name).strip("-") or "run"


def link_runs(results: dict[str, dict], root: Path) -> dict[str, Path]:
    """One relative symlink ``root/<readable label>`` per successful run -> its run directory
    (replaced atomically when it exists). Returns label -> link."""
    links: dict[str, Path] = {}
    root.mkdir(parents=True, exist_ok=True)
    for label, r in results.items():
        if r.get("failed") or not r.get("run_dir"):
            continue
        link = root / readable_name(label)
        if link.exists() and not link.is_symlink():
            continue  # a real folder of the user's: leave it alone
        target = os.path.relpath(Path(r["run_dir"]).absolute(), root.absolute())
        tmp = root / f".{link.name}.tmp"
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        tmp.symlink_to(target, target_is_directory=True)
        tmp.replace(link)
        links[label] = link
    return links


def next_steps(links: dict[str, Path], results_md: Path, data: Path) -> str:
    """What to look at and what to type next, with the real paths."""
    lines = ["", f"runs (links to the run directories under {DEMO_ROOT / 'runs'}):"]
    width = max((len(str(p)) for p in links.values()), default=0)
    for label, link in links.items():
        lines.append(f"  {str(link):<{width}}  {label}")
    lines.append(f"table, charts and renders: {results_md} (and {results_md.parent}/quick_*.png)")
    splat = next((p for label, p in links.items() if "nerf views" in label.lower()), None) or next(iter(links.values()), None)
    if splat is not None:
        q = shlex.quote(str(splat))
        lines += ["", "next:",
                  f"  ns2gs-viewer {q}                      # browse it at http://127.0.0.1:7007",
                  f"  ns2gs-export {q} --format ply        # standard 3DGS PLY -> {splat}/export/splat.ply",
                  f"  ns2gs-eval {q}                        # PSNR/SSIM/LPIPS per split -> {splat}/eval.json",
                  f"  ns2gs-train splatfacto --data {shlex.quote(str(data))} --augment-from {shlex.quote(str(links.get('StreetNeRF', splat)))}"]
    return "\n".join(lines)
