"""Fault injection: random byte flips and truncations over every file of a tiny dataset (nerfstudio
and COLMAP) and of a trained run (config, checkpoint, logs), and kill -9 at random moments of a
tiny training followed by a resume.

Every case must end in finite output or in one of the package's errors (:class:`UserError`: the
one line ``error: <file>: <what>``), never an unexpected exception (a traceback), a hang or more
than 2 GB of memory. Shared by ``tests/bench/test_faults.py`` (in ``make test``) and
``ns2gs-bench faults`` (``benchmarks/results/faults.json``).
"""

from __future__ import annotations

import dataclasses
import json
import os
import random
import resource
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import torch

HANG_S = 20.0  # one case longer than this is a hang
MEMORY_LIMIT = 2 << 30  # address space a case may add


@dataclass
class FaultCase:
    target: str  # "nerfstudio" | "colmap" | "run"
    file: str  # relative to the target's root
    kind: str  # "flip" | "truncate"
    offsets: list[int] = field(default_factory=list)  # flip: byte offsets (XOR with a nonzero byte); truncate: [new length]
    xor: list[int] = field(default_factory=list)


@dataclass
class FaultResult:
    case: FaultCase
    outcome: str  # ok | clean_error | traceback | hang | wrong_result
    detail: str = ""
    seconds: float = 0.0


class _Hang(BaseException):
    pass


# ------------------------------------------------------------------ fixtures
def write_colmap_copy(nerfstudio_root: Path, out: Path) -> Path:
    """The tiny nerfstudio scene as a COLMAP binary model (same images and poses)."""
    import numpy as np
    import pycolmap

    from nerf2gs_plugin.cameras import opengl_c2w_to_opencv_w2c
    from nerf2gs_plugin.data.ply import read_ply_points

    meta = json.loads((nerfstudio_root / "transforms.json").read_text())
    rec = pycolmap.Reconstruction()
    cam = pycolmap.Camera(model="PINHOLE", width=meta["w"], height=meta["h"],
                          params=[meta["fl_x"], meta["fl_y"], meta["cx"], meta["cy"]], camera_id=1)
    rec.add_camera_with_trivial_rig(cam)
    (out / "images").mkdir(parents=True, exist_ok=True)
    for i, fr in enumerate(meta["frames"]):
        name = Path(fr["file_path"]).name
        shutil.copy(nerfstudio_root / fr["file_path"], out / "images" / name)
        c2w = torch.tensor(fr["transform_matrix"], dtype=torch.float64)[None, :3]
        w2c = opengl_c2w_to_opencv_w2c(c2w)[0, :3].numpy()
        rec.add_image_with_trivial_frame(pycolmap.Image(name=name, camera_id=1, image_id=i + 1), pycolmap.Rigid3d(w2c))
    xyz, rgb = read_ply_points(nerfstudio_root / meta["ply_file_path"])
    for p, c in zip(xyz[:64].astype(np.float64), rgb[:64]):
        rec.add_point3D(p, pycolmap.Track(), c)
    model = out / "sparse" / "0"
    model.mkdir(parents=True, exist_ok=True)
    rec.write(str(model))
    return out


def train_tiny_run(data: Path, out: Path, method: str = "voxel-grid", steps: int = 6, **kw: Any):
    """A finished tiny run (its trainer is returned: the history holds every step's loss)."""
    from nerf2gs_plugin.engine.trainer import Trainer

    trainer = Trainer(tiny_config(data, out, method, steps, **kw))
    trainer.setup()
    trainer.train()
    return trainer


def tiny_config(data: Path, out: Path, method: str, steps: int, **kw: Any):
    from nerf2gs_plugin.registry import get_method

    kw.setdefault("steps_per_save", max(1, steps // 2))
    kw.setdefault("timestamp", "run")
    return dataclasses.replace(get_method(method).config, data=Path(data), output_dir=Path(out), max_num_iterations=steps,
                               steps_per_eval_image=0, progress=False, **kw)


# ------------------------------------------------------------------ cases
def _files(root: Path) -> list[str]:
    skip = {".lock"}
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")
                  if p.is_file() and p.name not in skip and ".ns2gs_cache" not in p.parts)


def make_cases(roots: dict[str, Path], n: int, seed: int = 0) -> list[FaultCase]:
    """``n`` cases round-robin over every file of every root: flips (1-4 bytes) and truncations."""
    rng = random.Random(seed)
    pools = {t: [(f, (roots[t] / f).stat().st_size) for f in _files(roots[t])] for t in roots}
    for pool in pools.values():
        rng.shuffle(pool)
    targets = list(roots)
    cases = []
    for i in range(n):
        target = targets[i % len(targets)]  # an equal share per target, then every file in turn
        pool = pools[target]
        name, size = pool[(i // len(targets)) % len(pool)]
        if size == 0 or i % 2:
            cases.append(FaultCase(target, name, "truncate", [rng.randrange(0, max(size, 1))]))
        else:
            k = rng.randint(1, 4)
            cases.append(FaultCase(target, name, "flip", [rng.randrange(size) for _ in range(k)], [rng.randint(1, 255) for _ in range(k)]))
    return cases


def apply_fault(path: Path, case: FaultCase) -> None:
    data = bytearray(path.read_bytes())
    if case.kind == "truncate":
        data = data[: case.offsets[0]]
    else:
        for off, x in zip(case.offsets, case.xor):
            data[off] ^= x
    path.write_bytes(bytes(data))


def _check_dataset(root: Path) -> Optional[str]:
    """Parse every split and read every image and mask; a non-finite value is a wrong result."""
    from nerf2gs_plugin.data import list_splits, parse_dataset
    from nerf2gs_plugin.datamanagers.image_set import load_image_set

    for split in list_splits(root):
        out = parse_dataset(root, split)
        ims = load_image_set(out)
        c = out.cameras
        for name, t in (("poses", c.camera_to_worlds), ("fx", c.fx), ("fy", c.fy), ("cx", c.cx), ("cy", c.cy), ("pixels", ims.pixels)):
            if not torch.isfinite(t.float()).all():
                return f"{split}: non-finite {name}"
        if out.points3D_xyz is not None and not torch.isfinite(out.points3D_xyz).all():
            return f"{split}: non-finite points"
    return None


def _check_run(run_dir: Path, data: Path) -> Optional[str]:
    """Load the run as eval/export do and render one view: it must be finite."""
    from nerf2gs_plugin.runs.load import load_run

    run = load_run(run_dir, data=data)
    cams = run.pipeline.datamanager.train_images.cameras
    with torch.no_grad():
        rgb = run.pipeline.model.render_camera(cams[0])["rgb"]
    return None if torch.isfinite(rgb).all() else "render is non-finite"


def run_case(case: FaultCase, roots: dict[str, Path], scratch: Path, data_for_run: Path) -> FaultResult:
    from nerf2gs_plugin.errors import UserError

    work = scratch / "case"
    shutil.rmtree(work, ignore_errors=True)
    shutil.copytree(roots[case.target], work, ignore=shutil.ignore_patterns(".ns2gs_cache", ".lock"))
    apply_fault(work / case.file, case)
    t0 = time.perf_counter()
    old = signal.signal(signal.SIGALRM, _raise_hang)
    signal.setitimer(signal.ITIMER_REAL, HANG_S)
    try:
        bad = _check_run(work, data_for_run) if case.target == "run" else _check_dataset(work)
        outcome, detail = ("wrong_result", bad) if bad else ("ok", "")
    except _Hang:
        outcome, detail = "hang", f"over {HANG_S:g} s"
    except UserError as e:
        msg = str(e)
        named = "/" in msg or "--" in msg
        outcome, detail = ("clean_error", msg.splitlines()[0]) if named and "\n" not in msg.strip() else ("traceback", f"unnamed or multi-line error: {msg!r}")
    except MemoryError:
        outcome, detail = "traceback", "MemoryError (over the 2 GB limit)"
    except Exception as e:  # noqa: BLE001 - exactly what the suite counts
        outcome, detail = "traceback", f"{type(e).__name__}: {str(e)[:200]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return FaultResult(case, outcome, detail, time.perf_counter() - t0)


def _raise_hang(signum, frame):  # noqa: ANN001
    raise _Hang()


def _limit_memory() -> None:
    """Cap the address space at what is mapped now + 2 GB: an allocation bomb fails fast."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                now = int(line.split()[1]) * 1024
                resource.setrlimit(resource.RLIMIT_AS, (now + MEMORY_LIMIT, resource.RLIM_INFINITY))
    except (OSError, ValueError):
        pass


# ------------------------------------------------------------------ kill -9 then resume
def kill_resume_cases(data: Path, work: Path, n: int = 5, seed: int = 0, method: str = "voxel-grid",
                      steps: int = 100000, steps_per_save: int = 5) -> list[FaultResult]:
    """``n`` trainings (run concurrently) killed with SIGKILL at a random moment (0.1-2 s after
    their first checkpoint: mid-step, mid-save, mid-cleanup); each resumes from its last
    checkpoint with the next step and the same loss as an uninterrupted run at that step."""
    from nerf2gs_plugin.engine.checkpoints import list_checkpoints, load_checkpoint
    from nerf2gs_plugin.engine.trainer import Trainer

    rng = random.Random(seed)
    exe = [sys.executable, "-m", "nerf2gs_plugin.cli.train", method, "--data", str(data), "--output-dir", str(work / "killed"),
           "--max-num-iterations", str(steps), "--steps-per-save", str(steps_per_save), "--steps-per-eval-image", "0",
           "--progress", "False"]
    delays = [rng.uniform(0.1, 2.0) for _ in range(n)]
    procs = [subprocess.Popen(exe + ["--timestamp", f"k{i}"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for i in range(n)]
    method_name = tiny_config(data, work, method, steps).method_name
    run_dirs = [work / "killed" / Path(data).name / method_name / f"k{i}" for i in range(n)]
    started: list[Optional[float]] = [None] * n
    t_end = time.time() + 240
    while any(p.poll() is None for p in procs):
        now = time.time()
        for i, p in enumerate(procs):
            if p.poll() is not None:
                continue
            if started[i] is None and list_checkpoints(run_dirs[i]):
                started[i] = now
            if (started[i] is not None and now - started[i] >= delays[i]) or now > t_end:
                p.send_signal(signal.SIGKILL)
                p.wait()
        time.sleep(0.02)
    found = []
    for i, p in enumerate(procs):
        case = FaultCase("training", f"k{i}", "kill -9", [int(delays[i] * 1000)])
        if p.returncode != -signal.SIGKILL:
            found.append((case, None, f"exit {p.returncode}: {p.stderr.read().decode()[-300:]}"))
            continue
        try:
            ckpts = list_checkpoints(run_dirs[i])
            step = int(load_checkpoint(ckpts[-1])["step"])  # the newest must load: atomic writes
            log = json.loads((run_dirs[i] / "train_log.json").read_text())
            if int(log["history"][-1]["step"]) < step:  # written before the checkpoint: never behind it
                found.append((case, None, f"train_log.json ends at step {log['history'][-1]['step']}, behind the checkpoint at {step}"))
                continue
            found.append((case, ckpts[-1], step))
        except Exception as e:  # noqa: BLE001
            found.append((case, None, f"{type(e).__name__}: {e}"))
    # the uninterrupted reference, as far as the furthest resume needs
    need = max([s for _, c, s in found if c is not None] + [0]) + 1
    ref = Trainer(tiny_config(data, work / "ref", method, steps, steps_per_save=steps_per_save))
    ref.setup()
    ref_loss = {s: ref.train_step(s)["loss"] for s in range(need + 1)}
    results = []
    for i, (case, ckpt, step) in enumerate(found):
        if ckpt is None:
            results.append(FaultResult(case, "traceback" if "exit" in str(step) or "Error" in str(step) else "wrong_result", str(step)))
            continue
        t0 = time.perf_counter()
        try:
            cfg = tiny_config(data, work / "resumed", method, steps, steps_per_save=steps_per_save, timestamp=f"r{i}", load_checkpoint=ckpt)
            trainer = Trainer(cfg)
            trainer.setup()
            loss = trainer.train_step(trainer.step)["loss"]
            want = step + 1
            same = trainer.step == want and abs(loss - ref_loss[want]) <= 1e-5 * max(1.0, abs(ref_loss[want]))
            detail = (f"killed {delays[i]:.2f} s after its first checkpoint; resumed at step {trainer.step} (checkpoint {step}); "
                      f"loss {loss:.6f}, uninterrupted {ref_loss[want]:.6f}")
            results.append(FaultResult(case, "ok" if same else "wrong_result", detail, time.perf_counter() - t0))
        except Exception as e:  # noqa: BLE001
            results.append(FaultResult(case, "traceback", f"{type(e).__name__}: {e}", time.perf_counter() - t0))
    return results


# ------------------------------------------------------------------ the suite
def fault_roots(work: Path, method: str = "voxel-grid") -> tuple[dict[str, Path], Path]:
    """Pristine tiny nerfstudio and COLMAP datasets and a trained run (made once under ``work``)."""
    ns = work / "nerfstudio"
    if not (ns / "transforms.json").is_file():
        _tiny_scene_module().write_tiny_scene(ns, n_train=4, w=24, h=16)
    cm = work / "colmap"
    if not (cm / "sparse" / "0" / "cameras.bin").is_file():
        write_colmap_copy(ns, cm)
    run = work / "runs" / ns.name / method / "run"
    if not any((run / "checkpoints").glob("*.ckpt")) if (run / "checkpoints").is_dir() else True:
        shutil.rmtree(run, ignore_errors=True)
        train_tiny_run(ns, work / "runs", method, steps=4)
    return {"nerfstudio": ns, "colmap": cm, "run": run}, ns


def _tiny_scene_module():
    """tests/tiny_scene.py of this checkout (the analytic scene the engine tests train on)."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "tests" / "tiny_scene.py"
    spec = importlib.util.spec_from_file_location("nerf2gs_tiny_scene", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run_file_faults(work: Path, n: int = 120, seed: int = 0, method: str = "voxel-grid") -> list[FaultResult]:
    roots, data = fault_roots(work, method)
    return [run_case(c, roots, work / "scratch", data) for c in make_cases(roots, n, seed)]


def summarize(results: list[FaultResult]) -> dict[str, Any]:
    counts = {k: sum(r.outcome == k for r in results) for k in ("ok", "clean_error", "traceback", "hang", "wrong_result")}
    return {"cases": len(results), "finite_ok": counts["ok"], "clean_errors": counts["clean_error"],
            "tracebacks": counts["traceback"], "hangs": counts["hang"], "wrong_results": counts["wrong_result"]}


def worker_main(argv: list[str]) -> None:
    """``python -m nerf2gs_bench.faults WORK N SEED METHOD OUT.json``: file faults in a
    process whose address space is capped (so 'more than 2 GB' fails instead of swapping)."""
    work, n, seed, method, out = Path(argv[0]), int(argv[1]), int(argv[2]), argv[3], Path(argv[4])
    fault_roots(work, method)  # imports and fixtures before the cap
    _limit_memory()
    results = run_file_faults(work, n, seed, method)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out.write_text(json.dumps({"peak_rss_mb": peak_mb, "results": [dataclasses.asdict(r) for r in results]}))


def run_suite(work: Path, n_files: int = 120, n_kills: int = 5, seed: int = 0, method: str = "voxel-grid") -> dict[str, Any]:
    """File faults in a memory-capped worker process plus kill -9 cases; the summary and every case."""
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    out = work / "file_faults.json"
    t0 = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH")])))
    p = subprocess.run([sys.executable, "-m", "nerf2gs_bench.faults", str(work), str(n_files), str(seed), method, str(out)],
                       capture_output=True, text=True, timeout=600, env=env)
    if p.returncode != 0:
        raise RuntimeError(f"fault worker failed ({p.returncode}): {p.stderr[-2000:]}")
    doc = json.loads(out.read_text())
    file_results = [FaultResult(FaultCase(**r["case"]), r["outcome"], r["detail"], r["seconds"]) for r in doc["results"]]
    t_files = time.perf_counter() - t0
    t1 = time.perf_counter()
    kill_results = kill_resume_cases(fault_roots(work, method)[1], work / "kill", n_kills, seed, method)
    t_kills = time.perf_counter() - t1
    everything = file_results + kill_results
    summary = summarize(everything)
    summary.update({
        "file_cases": len(file_results), "kill_cases": len(kill_results), "seed": seed, "method": method,
        "peak_rss_mb_file_cases": round(doc["peak_rss_mb"], 1), "max_case_seconds": round(max(r.seconds for r in file_results), 2),
        "seconds_file_cases": round(t_files, 1), "seconds_kill_cases": round(t_kills, 1),
        "by_target": {t: summarize([r for r in everything if r.case.target == t]) for t in sorted({r.case.target for r in everything})},
    })
    return {"summary": summary, "cases": [dataclasses.asdict(r) for r in everything]}


if __name__ == "__main__":
    worker_main(sys.argv[1:])


def write_results(doc: dict[str, Any], out_dir: Path) -> tuple[Path, Path]:
    """``faults.json`` (summary at the top level, then every case) and ``faults.md``."""
    from nerf2gs_plugin.utils.io import atomic_write_text
    from nerf2gs_bench.machine import machine_info, machine_line

    s = doc["summary"]
    out_dir = Path(out_dir)
    js = out_dir / "faults.json"
    cap = doc.get("capture")
    extra = {"capture": {**cap["summary"], "case_list": cap["cases"]}} if cap else {}
    atomic_write_text(js, json.dumps({**s, "machine": machine_info(), "case_list": doc["cases"], **extra}, indent=1))
    rows = ["| target | cases | finite output | clean errors | tracebacks | hangs | wrong results |", "|---|---|---|---|---|---|---|"]
    for t, c in s["by_target"].items():
        rows.append(f"| {t} | {c['cases']} | {c['finite_ok']} | {c['clean_errors']} | {c['tracebacks']} | {c['hangs']} | {c['wrong_results']} |")
    rows.append(f"| **all** | {s['cases']} | {s['finite_ok']} | {s['clean_errors']} | {s['tracebacks']} | {s['hangs']} | {s['wrong_results']} |")
    md = "\n".join([
        "# Fault injection (`ns2gs-bench faults`)", "",
        f"{s['file_cases']} random byte flips / truncations (seed {s['seed']}) over every file of a tiny nerfstudio dataset, "
        f"its COLMAP binary twin and a trained `{s['method']}` run (config, checkpoint, logs); {s['kill_cases']} trainings "
        "killed with SIGKILL at a random moment, then resumed. A case passes with finite output (the dataset parses and every "
        "image, pose and point is finite; the run loads and renders finite) or with one of the package's one-line errors "
        "naming the file; a traceback, a hang (> 20 s) or non-finite output fails it. A resumed training must continue at the "
        "step after its last checkpoint with the loss of an uninterrupted run.", "",
        *rows, "",
        f"Peak memory of the file cases: {s['peak_rss_mb_file_cases']} MB (address space capped at +2 GB); slowest case "
        f"{s['max_case_seconds']} s; {s['seconds_file_cases']} s for the file cases, {s['seconds_kill_cases']} s for the kills.", "",
        *(_capture_md(cap["summary"]) if cap else []),
        f"Machine: {machine_line()}", ""])
    md_path = out_dir / "faults.md"
    atomic_write_text(md_path, md)
    return js, md_path


def _capture_md(c: dict[str, Any]) -> list[str]:
    """The capture path's table (``faults_capture``): per entry point."""
    rows = ["| entry point | cases | ok | clean errors | tracebacks | native aborts | hangs | wrong results |",
            "|---|---|---|---|---|---|---|---|"]
    for e, k in [*c["by_entry"].items(), ("**all**", c)]:
        rows.append(f"| {e} | {k['cases']} | {k['ok']} | {k['clean_error']} | {k['traceback']} | {k['abort']} | {k['hang']} | {k['wrong_result']} |")
    return ["## Capture path", "",
            "The commands a user runs on a capture (`ns2gs-data process images|video`, `ns2gs-data masks` with an ONNX "
            "segmenter and auto, `ns2gs-enhance apply`, `ns2gs-eval`), each in a subprocess: byte flips, truncations and "
            "junk in their inputs (photos, video, models, checkpoint, config, dataset), NaN / inf / out-of-range / odd-layout "
            "ONNX models, kill -9 mid-run then the same command again, two runs at once, bad flags. A case passes with exit 0 "
            "and a result that checks out, or with one `error:` line (exit 2) that left every earlier result as it was and "
            "wrote none from the bad input.", "", *rows, "", f"Slowest case {c['max_case_seconds']} s.", ""]
