"""``ns2gs-bench paper-scale-real``: StreetNeRF's ``paper`` preset (16x2^19 hash grid, 256/96/48
samples, 4096 rays) on a processed real capture, within a wall-clock budget, beside the default
(CPU-scale) StreetNeRF on the same device and data: held-out PSNR (all pixels and static ones where
masks exist), train time, steps/s, the time the full 25k-step schedule would take at that rate, render
FPS and model size. A short probe measures the paper preset's rate; the budget then sets its steps,
with the whole schedule rescaled to them (``--steps``). Writes ``paper_scale_real_<name>.{json,md}``."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Any, Optional

from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_plugin.utils.io import atomic_write_text

HELD_OUT = ("test", "street")  # every 8th frame of a capture without split keys; a synthetic street's street views


def _config(data: Path, runs: Path, name: str, preset: Optional[str], steps: Optional[int], device: str):
    from nerf2gs_plugin.cli.train import parse_args  # noqa: PLC0415

    args = ["streetnerf"] + (["--preset", preset] if preset else []) + (["--steps", str(steps)] if steps else [])
    args += ["--data", str(data), "--output-dir", str(runs), "--experiment-name", name, "--device", device,
             "--steps-per-eval-image", "0"]
    return parse_args(args)[0]


def _train(config) -> tuple[Path, float]:
    from nerf2gs_plugin.engine.trainer import Trainer  # noqa: PLC0415

    trainer = Trainer(config)
    trainer.setup()
    run_dir = Path(trainer.train())
    return run_dir, float(json.loads((run_dir / "train_log.json").read_text())["train_seconds"])


def _evaluate(run_dir: Path, device: str) -> dict[str, Any]:
    from nerf2gs_plugin.engine.trainer import pick_device  # noqa: PLC0415
    from nerf2gs_plugin.eval.evaluate import evaluate_run  # noqa: PLC0415
    from nerf2gs_plugin.runs.load import load_run  # noqa: PLC0415

    run = load_run(run_dir, device=pick_device(device))
    name = next((s for s in HELD_OUT if s in run.pipeline.datamanager.eval_split_names()), None)
    if name is None:
        raise ValueError(f"{run.config.data}: no held-out split ({' or '.join(HELD_OUT)})")
    result = evaluate_run(run, [name], render_dir=run_dir / "eval_renders")
    atomic_write_text(run_dir / "eval.json", json.dumps(result, indent=2))
    split = result["results"][name]
    return {"split": name, "psnr": split.get("psnr"), "static_psnr": split.get("static_psnr"), "ssim": split.get("ssim"),
            "lpips": split.get("lpips"), "images": split.get("num_images"), "fps": result.get("fps"),
            "size": result.get("size")}


def steps_for_budget(seconds_per_step: float, budget_s: float, full: int, floor: int = 200) -> int:
    """Steps that fit ``budget_s`` at the measured rate, in hundreds, between ``floor`` and ``full``."""
    return int(max(floor, min(full, budget_s / max(seconds_per_step, 1e-6) // 100 * 100)))


def run(data: Path, out: Path, runs: Path, budget_s: float = 240.0, probe_steps: int = 100, device: str = "auto",
        name: Optional[str] = None, with_default: bool = True, min_steps: int = 200,
        default_steps: Optional[int] = None) -> dict[str, Any]:
    from nerf2gs_plugin.methods.streetnerf.config import DEFAULT_STEPS, PAPER_STEPS  # noqa: PLC0415

    data, name = Path(data), name or Path(data).resolve().name
    t_all = time.perf_counter()
    probe = dataclasses.replace(_config(data, runs, f"{name}_probe", "paper", None, device), max_num_iterations=probe_steps)
    _, probe_s = _train(probe)
    rate = probe_s / probe_steps  # includes the first steps' warm-up: errs towards fewer steps
    steps = steps_for_budget(rate, budget_s, PAPER_STEPS, min_steps)
    rows: dict[str, dict[str, Any]] = {}
    plan = [("paper", "paper", steps)] + ([("default", None, default_steps)] if with_default else [])
    for label, preset, n in plan:
        config = _config(data, runs, f"{name}_{label}", preset, n, device)
        run_dir, seconds = _train(config)
        rows[label] = {"steps": config.max_num_iterations, "train_seconds": seconds,
                       "steps_per_second": config.max_num_iterations / seconds, "run": str(run_dir),
                       "rays_per_batch": config.pipeline.datamanager.rays_per_batch, **_evaluate(run_dir, device)}
    rows["paper"]["full_schedule_minutes"] = PAPER_STEPS / rows["paper"]["steps_per_second"] / 60
    doc = {"data": str(data), "name": name, "device": device, "budget_s": budget_s, "probe_steps": probe_steps,
           "probe_seconds_per_step": rate, "paper_steps_full": PAPER_STEPS, "default_steps": DEFAULT_STEPS,
           "rows": rows, "seconds": time.perf_counter() - t_all, "machine": machine_info()}
    import torch  # noqa: PLC0415

    if torch.cuda.is_available():
        doc["gpu"] = torch.cuda.get_device_name()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / f"paper_scale_real_{name}.json", json.dumps(doc, indent=1, default=str))
    atomic_write_text(out / f"paper_scale_real_{name}.md", markdown(doc))
    return doc


def _cell(v: Any, spec: str) -> str:
    return format(v, spec) if isinstance(v, (int, float)) else "n/a"


def markdown(doc: dict[str, Any]) -> str:
    gpu = f" ({doc['gpu']})" if doc.get("gpu") else ""
    lines = [f"# StreetNeRF at paper scale on a real capture: {doc['name']}", "",
             f"Machine: {machine_line(doc['machine'])}{gpu}; device `{doc['device']}`.",
             f"The `paper` preset trained for the steps its measured rate fits in {doc['budget_s']:.0f} s (probe of "
             f"{doc['probe_steps']} steps: {doc['probe_seconds_per_step'] * 1e3:.0f} ms/step), its whole schedule rescaled "
             f"to them; the default (CPU-scale) StreetNeRF on the same device beside it. Held-out: every 8th frame.", "",
             "| config | steps | rays/batch | train (s) | steps/s | PSNR | static PSNR | SSIM | LPIPS | render FPS | MB |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label, r in doc["rows"].items():
        size = r.get("size") or {}
        lines.append(f"| {label} | {r['steps']} | {r['rays_per_batch']} | {r['train_seconds']:.0f} | {r['steps_per_second']:.1f} | "
                     f"{_cell(r.get('psnr'), '.2f')} | {_cell(r.get('static_psnr'), '.2f')} | {_cell(r.get('ssim'), '.3f')} | "
                     f"{_cell(r.get('lpips'), '.3f')} | {_cell(r.get('fps'), '.1f')} | {_cell(size.get('megabytes'), '.1f')} |")
    p = doc["rows"]["paper"]
    lines += ["", f"The full paper schedule ({doc['paper_steps_full']:,} steps) would take about "
              f"{p['full_schedule_minutes']:.0f} min at this rate."]
    return "\n".join(lines) + "\n"
