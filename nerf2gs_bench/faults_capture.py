"""Fault injection on the capture path, through the command line as a user runs it: ``process``
(photos and video), ``masks`` (onnx and auto), ``enhance apply`` and ``eval``, with byte flips and
truncations of their inputs (a config cut at a line break too), NaN / out-of-range / odd-layout
models, kill -9 mid-run (then the same command again), two runs at once and a disk that fills up
during the SfM (a file size limit).

Each case runs the real command in a subprocess and is classified from its exit status, its
stderr and what it left on disk:

* ``ok``: exit 0 and what it wrote checks out (the dataset parses with finite poses, every mask
  and enhanced image is there and decodes, eval.json holds finite figures);
* ``clean_error``: exit 2, the last stderr line ``error: ...``, and nothing written from the bad
  input (the outputs that existed before are byte-identical, no new result file);
* ``traceback`` (a Python traceback or an unclean exit), ``abort`` (killed by a signal of its own:
  a native crash, SIGABRT), ``hang`` (over the case's time limit), ``wrong_result`` (exit 0 with a
  result that does not check out, or an error that still wrote or replaced a result).

Shared by ``tests/bench/test_faults_capture.py`` (a subset) and ``ns2gs-bench faults`` (all).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

OUTCOMES = ("ok", "clean_error", "traceback", "abort", "hang", "wrong_result")
NUM_PHOTOS = 16
CASE_TIMEOUT_S = 120.0  # one command longer than this is a hang (process runs SfM: ~10 s here)
ROOT = Path(__file__).resolve().parents[1]


@dataclass
class CaptureCase:
    entry: str  # "process images" | "process video" | "masks onnx" | "masks auto" | "enhance apply" | "eval"
    fault: str  # "flip" | "truncate" | "bad model" | "kill -9" | "concurrent" | "bad flag" | ...
    what: str  # the file or model the fault is in
    params: dict[str, Any] = field(default_factory=dict)


@dataclass
class CaptureResult:
    case: CaptureCase
    outcome: str
    detail: str = ""
    seconds: float = 0.0


# ------------------------------------------------------------------ running one command
@dataclass
class Ran:
    rc: Optional[int]  # None: timed out (killed by us)
    err: str
    killed_by_us: bool = False


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
                OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"))


def _cmd(module: str, args: list[Any]) -> list[str]:
    return [sys.executable, "-m", f"nerf2gs_plugin.cli.{module}", *map(str, args)]


def run_cmd(module: str, args: list[Any], timeout: float = CASE_TIMEOUT_S, cwd: Optional[Path] = None,
            preexec: Optional[Callable[[], None]] = None) -> Ran:
    try:
        p = subprocess.run(_cmd(module, args), capture_output=True, text=True, timeout=timeout, env=_env(), cwd=cwd,
                           preexec_fn=preexec)
        return Ran(p.returncode, p.stderr)
    except subprocess.TimeoutExpired as e:
        err = e.stderr.decode(errors="replace") if isinstance(e.stderr, bytes) else (e.stderr or "")
        return Ran(None, err)


def limit_file_size(limit: int) -> Callable[[], None]:
    """For ``preexec``: no file of the command grows past ``limit`` bytes, a write beyond fails (EFBIG,
    SIGXFSZ ignored), as when another writer fills the disk while it runs."""
    import resource

    def pre() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return pre


def run_killed(module: str, args: list[Any], delay: float, cwd: Optional[Path] = None) -> Ran:
    """Start the command and SIGKILL it ``delay`` seconds later (or let it finish first)."""
    p = subprocess.Popen(_cmd(module, args), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env(), cwd=cwd)
    try:
        _, err = p.communicate(timeout=delay)
        return Ran(p.returncode, err.decode(errors="replace"))
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
        return Ran(p.returncode, err.decode(errors="replace"), killed_by_us=True)


def run_concurrent(module: str, arg_lists: list[list[Any]], stagger: float = 0.0, timeout: float = CASE_TIMEOUT_S) -> list[Ran]:
    procs = []
    for i, args in enumerate(arg_lists):
        if i and stagger:
            time.sleep(stagger)
        procs.append(subprocess.Popen(_cmd(module, args), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env()))
    out = []
    t_end = time.time() + timeout
    for p in procs:
        try:
            _, err = p.communicate(timeout=max(1.0, t_end - time.time()))
            out.append(Ran(p.returncode, err.decode(errors="replace")))
        except subprocess.TimeoutExpired:
            p.kill()
            _, err = p.communicate()
            out.append(Ran(None, err.decode(errors="replace")))
    return out


def classify(ran: Ran) -> tuple[str, str]:
    """(outcome, detail) from the exit alone: ok / clean_error / traceback / abort / hang."""
    err = ran.err.strip()
    last = err.splitlines()[-1] if err else ""
    if ran.rc is None:
        return "hang", f"over {CASE_TIMEOUT_S:g} s"
    if "Traceback (most recent call last)" in err or "Fatal Python error" in err:
        i = err.find("Traceback")
        return ("abort" if "Fatal Python error" in err else "traceback"), (err[i:][-300:] if i >= 0 else err[-300:])
    if ran.rc < 0 or ran.rc in (134, 136, 139):
        return "abort", f"exit {ran.rc}: {err[-200:]}"
    if ran.rc == 0:
        return "ok", ""
    if ran.rc == 2 and last.startswith("error: ") and len(last) < 600:
        return "clean_error", last
    return "traceback", f"exit {ran.rc} without one error line: {err[-300:]}"


# ------------------------------------------------------------------ what a result must look like
def _digest(paths: list[Path]) -> dict[str, str]:
    out = {}
    for root in paths:
        root = Path(root)
        files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file()) if root.is_dir() else []
        for p in files:
            if ".lock" in p.name or ".ns2gs_cache" in p.parts:
                continue
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def check_dataset(root: Path) -> Optional[str]:
    """A written dataset: its train split parses, every pose and image is finite."""
    import torch

    from nerf2gs_plugin.data import parse_dataset
    from nerf2gs_plugin.datamanagers.image_set import load_image_set

    out = parse_dataset(root, "train")
    if not torch.isfinite(out.cameras.camera_to_worlds).all():
        return "non-finite poses"
    if not torch.isfinite(load_image_set(out).pixels).all():
        return "non-finite pixels"
    return None


def check_masks(root: Path, images: list[str]) -> Optional[str]:
    from nerf2gs_plugin.data.images import load_mask

    for kind in ("sky", "ground", "transient"):
        for name in images:
            p = root / "masks" / kind / f"{Path(name).stem}.png"
            if not p.is_file():
                return f"missing {p.relative_to(root)}"
            load_mask(p)
    return None


def check_images(paths: list[Path], against: Optional[dict[str, Any]] = None) -> Optional[str]:
    import numpy as np

    from nerf2gs_plugin.data.images import load_image

    for p in paths:
        if not p.is_file():
            return f"missing {p.name}"
        img = load_image(p)
        if against is not None and float(np.abs(img.numpy() - against[p.name]).mean()) > 0.05:
            return f"{p.name} differs from the identity model's output"
    return None


def check_eval_json(path: Path) -> Optional[str]:
    doc = json.loads(path.read_text())
    for split, r in doc["results"].items():
        if not r.get("num_images") or not all(isinstance(r.get(k), float) and math.isfinite(r[k]) for k in ("psnr", "ssim")):
            return f"split {split}: {r.get('num_images')} images, psnr {r.get('psnr')}"
    return None


# ------------------------------------------------------------------ fixtures
@dataclass
class Fixtures:
    photos: Path  # a short forward drive, PNG photos
    video: Path  # the same frames as an MJPG video
    data: Path  # tiny nerfstudio dataset with eval splits (no masks: for `masks`)
    run: Path  # a trained run on ``masked`` (for `eval` and as the auto masks' reference)
    masked: Path  # the same dataset with masks (the run's)
    models: Path  # good and bad ONNX models


def make_fixtures(work: Path) -> Fixtures:
    """Made once under ``work`` (a few seconds): the inputs every case copies before breaking them."""
    import cv2

    from nerf2gs_bench.faults import fault_roots
    from nerf2gs_bench.fault_models import ENHANCERS, SEGMENTERS, conv_model

    work = Path(work)
    roots, masked = fault_roots(work / "train_fixtures")
    street = work / "street"
    if not (street / "transforms.json").is_file():
        from nerf2gs_plugin.data.synthetic_street import SynthStreetConfig, generate_street

        generate_street(SynthStreetConfig(out=street, seed=0, width=200, height=112, num_train=80, num_street=1, num_bev=1,
                                          num_val_street=1, num_val_bev=1, num_cars=2, spp=4, num_points=100, progress=False))
    photos = work / "photos"
    if not photos.is_dir():
        photos.mkdir()
        for i in range(NUM_PHOTOS):  # consecutive views of the forward pass, ~1.3 m apart: all register
            shutil.copy(street / "images" / f"train_{i + 10:04d}.png", photos / f"f{i:03d}.png")
    video = work / "drive.avi"
    if not video.is_file():
        frames = [cv2.imread(str(p)) for p in sorted(photos.iterdir())]
        h, w = frames[0].shape[:2]
        wr = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (w, h))
        for f in frames:
            wr.write(f)
        wr.release()
    data = work / "maskless"
    if not (data / "transforms.json").is_file():
        shutil.copytree(masked, data, ignore=shutil.ignore_patterns("masks", ".ns2gs_cache"))
    models = work / "models"
    models.mkdir(exist_ok=True)
    conv_model(models / "enhance_identity.onnx", identity_scale=1.0)
    conv_model(models / "segment_road.onnx", out_channels=19, weight=0.0)  # every pixel: class 0 (road)
    for name, kw in ENHANCERS.items():
        conv_model(models / f"enhance_{name}.onnx", **kw)
    for name, kw in SEGMENTERS.items():
        conv_model(models / f"segment_{name}.onnx", **kw)
    (models / "segment_ids_huge.onnx.json").write_text(json.dumps({"classes": "cityscapes"}))
    (models / "segment_ids_negative.onnx.json").write_text(json.dumps({"classes": "cityscapes"}))
    return Fixtures(photos, video, data, roots["run"], masked, models)


# ------------------------------------------------------------------ faults
def flip(path: Path, rng: random.Random, k: Optional[int] = None) -> str:
    data = bytearray(path.read_bytes())
    offs = [rng.randrange(len(data)) for _ in range(k or rng.randint(1, 4))]
    for o in offs:
        data[o] ^= rng.randint(1, 255)
    path.write_bytes(bytes(data))
    return f"flipped bytes {offs}"


def cut_at_line(path: Path, rng: random.Random) -> str:
    """Keep the first lines of a text file, up to a line break (a file cut short that still parses)."""
    lines = path.read_bytes().splitlines(keepends=True)
    n = rng.randrange(1, len(lines))
    path.write_bytes(b"".join(lines[:n]))
    return f"cut after line {n} of {len(lines)}"


def truncate(path: Path, rng: random.Random, to: Optional[int] = None) -> str:
    data = path.read_bytes()
    n = rng.randrange(len(data)) if to is None else to
    path.write_bytes(data[:n])
    return f"truncated to {n} of {len(data)} bytes"


def break_file(path: Path, kind: str, rng: random.Random) -> str:
    if kind == "flip":
        return flip(path, rng)
    if kind == "truncate":
        return truncate(path, rng)
    if kind == "empty":
        return truncate(path, rng, 0)
    if kind == "cut at a line":
        return cut_at_line(path, rng)
    if kind == "junk":
        path.write_bytes(bytes(rng.randrange(256) for _ in range(2048)))
        return "replaced by 2 KB of random bytes"
    raise ValueError(kind)


# ------------------------------------------------------------------ one case per entry point
Runner = Callable[[CaptureCase, Fixtures, Path, random.Random], tuple[str, str]]


def _judge(ran: Ran, before: dict[str, str], after_paths: list[Path], check_ok: Callable[[], Optional[str]],
           must_fail: bool = False, fresh: Optional[list[Path]] = None) -> tuple[str, str]:
    """The outcome of one command: its exit, then what it left. ``before``: digests of the results
    that existed (an error must leave them as they were); ``fresh``: result paths that must not
    exist after an error; ``must_fail``: bad input (a model, flag or file), exit 0 is a wrong result."""
    outcome, detail = classify(ran)
    if outcome == "ok":
        if must_fail:
            return "wrong_result", "exit 0 from bad input"
        bad = check_ok()
        return ("wrong_result", bad) if bad else ("ok", "")
    if outcome == "clean_error":
        if _digest(after_paths) != before and before:
            return "wrong_result", f"an error replaced a result: {detail}"
        for p in fresh or []:
            if Path(p).exists() and (Path(p).is_file() or any(q.is_file() for q in Path(p).rglob("*.png"))):
                return "wrong_result", f"an error left {Path(p).name} written: {detail}"
    return outcome, detail


def case_process(case: CaptureCase, fx: Fixtures, scratch: Path, rng: random.Random) -> tuple[str, str]:
    video = case.entry == "process video"
    src = scratch / ("drive.avi" if video else "photos")
    if video:
        shutil.copy(fx.video, src)
    else:
        shutil.copytree(fx.photos, src)
    out = scratch / "data"
    base = ["process", "video" if video else "images", src, "--out", out, "--no-progress", "--num-threads", "1",
            "--camera-height", "3.0", "--fov-deg", "80", *(["--num-frames", str(NUM_PHOTOS)] if video else [])]
    args = base + [str(a) for a in case.params.get("extra", [])]
    ok = lambda: check_dataset(out)  # noqa: E731
    if case.fault in ("flip", "truncate", "empty", "junk"):
        target = src if video else src / case.what
        note = break_file(target, case.fault, rng)
        outcome, detail = _judge(run_cmd("data", args), {}, [], ok, fresh=[out / "transforms.json"])
        return outcome, f"{note}; {detail}".strip("; ")
    if case.fault == "bad flag":
        return _judge(run_cmd("data", args), {}, [], ok, must_fail=True, fresh=[out / "transforms.json"])
    if case.fault == "kill -9":
        ran = run_killed("data", args, case.params["delay"])
        if not ran.killed_by_us:
            first = classify(ran)
            if first[0] not in ("ok", "clean_error"):
                return first
        outcome, detail = _judge(run_cmd("data", args), {}, [], ok)
        return outcome, f"killed after {case.params['delay']:.1f} s, then run again: {detail}".rstrip(": ")
    if case.fault == "disk fills":  # during the SfM: the database stops growing, the frames fit
        note = f"files limited to {case.params['limit'] // 1000} KB"
        outcome, detail = _judge(run_cmd("data", args, preexec=limit_file_size(case.params["limit"])), {}, [], ok, must_fail=True,
                                 fresh=[out / "transforms.json"])
        if outcome != "clean_error":
            return outcome, f"{note}: {detail}"
        again, more = _judge(run_cmd("data", args), {}, [], ok)  # with room again: it resumes and finishes
        return again, f"{note}: {detail}; then with room: {more or 'ok'}"
    if case.fault == "changed content":  # same names, other photos: the dataset must follow the new content
        first = run_cmd("data", args)
        if classify(first)[0] != "ok":
            return classify(first)
        others = sorted(fx.photos.iterdir())
        for p, q in zip(sorted(src.iterdir()), reversed(others)):  # the drive backwards under the same names
            shutil.copy(q, p)
        outcome, detail = _judge(run_cmd("data", args), {}, [], ok)
        if outcome == "ok":
            meta = json.loads((out / "transforms.json").read_text())
            for fr in meta["frames"]:
                stem = Path(fr["file_path"]).stem
                ours = [p for p in src.iterdir() if p.stem == stem]
                if ours and _same_pixels(out / fr["file_path"], ours[0]) is False:
                    return "wrong_result", f"{fr['file_path']} is still the old photo"
        return outcome, detail
    if case.fault == "concurrent":
        return judge_concurrent("data", args, lambda: check_dataset(out), stagger=case.params.get("stagger", 0.0),
                                check_after_errors=False)
    raise ValueError(case.fault)


def judge_concurrent(module: str, args: list[Any], check: Callable[[], Optional[str]], stagger: float = 0.0,
                     check_after_errors: bool = True) -> tuple[str, str]:
    """Two runs of one command on the same output at once: neither may fail other than with a clean error,
    and what they leave must check out (``check`` returns the problem, or None). ``check_after_errors``:
    check the output even when both runs were refused (it held a good earlier result)."""
    outs = [classify(r) for r in run_concurrent(module, [args, args], stagger=stagger)]
    bad = [o for o in outs if o[0] not in ("ok", "clean_error")]
    if bad:
        return bad[0]
    any_ok = any(o[0] == "ok" for o in outs)
    problem = check() if any_ok or check_after_errors else None
    if problem:
        return "wrong_result", problem
    return ("ok" if any_ok else "clean_error"), "; ".join(o[1] for o in outs if o[1])


def _same_pixels(a: Path, b: Path) -> Optional[bool]:
    import numpy as np

    from nerf2gs_plugin.data.images import load_image

    try:
        x, y = load_image(a).numpy(), load_image(b).numpy()
    except Exception:  # noqa: BLE001 - an unreadable output is judged elsewhere
        return None
    if x.shape != y.shape:
        return None  # resized on export: not comparable here
    return bool(np.abs(x - y).mean() < 0.02)


def case_masks(case: CaptureCase, fx: Fixtures, scratch: Path, rng: random.Random) -> tuple[str, str]:
    data = scratch / "data"
    shutil.copytree(fx.data, data)
    images = sorted(p.name for p in (data / "images").iterdir())
    if case.entry == "masks onnx":
        model = scratch / "model.onnx"
        name = case.params.get("model", "segment_road")
        shutil.copy(fx.models / f"{name}.onnx", model)
        if (fx.models / f"{name}.onnx.json").is_file():
            shutil.copy(fx.models / f"{name}.onnx.json", scratch / "model.onnx.json")
        args = ["masks", data, "--segmenter", f"onnx:{model}", "--no-progress"]
    else:
        ref = scratch / "ref"
        shutil.copytree(fx.run, ref, ignore=shutil.ignore_patterns(".lock"))
        model = ref / "checkpoints" / sorted(p.name for p in (ref / "checkpoints").iterdir())[-1]
        args = ["masks", data, "--segmenter", "auto", "--reference", ref, "--no-progress"]
    ok = lambda: check_masks(data, images)  # noqa: E731
    note = ""
    if case.fault in ("flip", "truncate", "empty", "junk"):
        target = {"model": model, "transforms.json": data / "transforms.json", "image": data / "images" / images[0],
                  "config.yml": scratch / "ref" / "config.yml"}[case.what]
        note = break_file(target, case.fault, rng) + "; "
    if case.fault == "kill -9":
        ran = run_killed("data", args, case.params["delay"])
        if not ran.killed_by_us and classify(ran)[0] not in ("ok", "clean_error"):
            return classify(ran)
        outcome, detail = _judge(run_cmd("data", args + ["--overwrite"]), {}, [], ok)
        left = sorted(p.name for p in data.glob(".masks-*.tmp"))
        if outcome == "ok" and left:  # the killed run's staging folder must not stay in the dataset
            outcome, detail = "wrong_result", f"left {', '.join(left)}"
        return outcome, f"killed after {case.params['delay']:.1f} s, then run again with --overwrite: {detail}".rstrip(": ")
    if case.fault == "concurrent":
        return judge_concurrent("data", args, ok, check_after_errors=False)
    outcome, detail = _judge(run_cmd("data", args), {}, [], ok, must_fail=case.fault == "bad model", fresh=[data / "masks"])
    return outcome, note + detail


def case_enhance(case: CaptureCase, fx: Fixtures, scratch: Path, rng: random.Random) -> tuple[str, str]:
    from nerf2gs_plugin.data.images import load_image

    folder = scratch / "imgs"
    folder.mkdir()
    names = sorted(p.name for p in (fx.photos).iterdir())[: case.params.get("n", 3)]
    for n in names:
        shutil.copy(fx.photos / n, folder / n)
    model = scratch / "model.onnx"
    shutil.copy(fx.models / f"{case.params.get('model', 'enhance_identity')}.onnx", model)
    out = folder if case.params.get("in_place", True) else scratch / "out"
    expected = {n: load_image(fx.photos / n).numpy() for n in names}
    args = ["apply", "--model", model, "--input", *[folder / n for n in names], "--output", out]
    ok = lambda: check_images([out / n for n in names], expected)  # noqa: E731
    note = ""
    if case.fault in ("flip", "truncate", "empty", "junk"):
        target = model if case.what == "model" else folder / names[0]
        note = break_file(target, case.fault, rng) + "; "
        if case.what != "model":  # a broken input image: the output, when any, is the identity of what decodes
            ok = lambda: check_images([out / n for n in names[1:]], expected)  # noqa: E731
    before = _digest([folder]) if out == folder else {}
    if case.fault == "kill -9":
        ran = run_killed("enhance", args, case.params["delay"])
        if not ran.killed_by_us and classify(ran)[0] not in ("ok", "clean_error"):
            return classify(ran)
        present = [out / n for n in names if (out / n).is_file()]
        bad = check_images(present)  # whatever a kill left decodes (atomic writes)
        if bad:
            return "wrong_result", f"after kill -9: {bad}"
        outcome, detail = _judge(run_cmd("enhance", args), {}, [], ok)
        return outcome, f"killed after {case.params['delay']:.1f} s, then run again: {detail}".rstrip(": ")
    if case.fault == "concurrent":
        return judge_concurrent("enhance", args, ok)
    outcome, detail = _judge(run_cmd("enhance", args), before, [folder] if out == folder else [], ok,
                             must_fail=case.fault == "bad model", fresh=[] if out == folder else [out])
    return outcome, note + detail


def case_eval(case: CaptureCase, fx: Fixtures, scratch: Path, rng: random.Random) -> tuple[str, str]:
    run = scratch / "run"
    shutil.copytree(fx.run, run, ignore=shutil.ignore_patterns(".lock", "eval.json", "eval_renders"))
    data = scratch / "data"
    shutil.copytree(fx.masked, data, ignore=shutil.ignore_patterns(".ns2gs_cache"))
    result = run / "eval.json"
    result.write_text(json.dumps({"results": {"street": {"num_images": 2, "psnr": 20.0, "ssim": 0.5}}, "note": "a good earlier result"}))
    args = [run, "--data", data, "--device", "cpu", *case.params.get("extra", [])]
    ok = lambda: check_eval_json(result)  # noqa: E731
    note = ""
    if case.fault in ("flip", "truncate", "empty", "junk", "cut at a line"):
        ckpt = sorted((run / "checkpoints").iterdir())[-1]
        target = {"checkpoint": ckpt, "config.yml": run / "config.yml", "image": data / "images" / "street_000.png",
                  "transforms.json": data / "transforms.json", "dataparser_transforms.json": run / "dataparser_transforms.json"}[case.what]
        note = break_file(target, case.fault, rng) + "; "
    elif case.fault == "bad config":
        (run / "config.yml").write_text(case.params["text"])
    before = _digest([result])
    if case.fault == "kill -9":
        ran = run_killed("eval", args, case.params["delay"])
        if not ran.killed_by_us and classify(ran)[0] not in ("ok", "clean_error"):
            return classify(ran)
        try:
            doc = json.loads(result.read_text())  # the old result or a whole new one, never half of one
        except (OSError, ValueError) as e:
            return "wrong_result", f"eval.json after kill -9: {e}"
        if "note" not in doc and check_eval_json(result):
            return "wrong_result", "eval.json after kill -9 does not check out"
        return "ok", f"killed after {case.params['delay']:.1f} s: eval.json {'kept' if 'note' in doc else 'complete'}"
    if case.fault == "concurrent":
        return judge_concurrent("eval", args, ok)
    outcome, detail = _judge(run_cmd("eval", args), before, [result], ok, must_fail=case.fault == "cut at a line")
    return outcome, note + detail


RUNNERS: dict[str, Runner] = {"process images": case_process, "process video": case_process, "masks onnx": case_masks,
                              "masks auto": case_masks, "enhance apply": case_enhance, "eval": case_eval}

ALIAS_BOMB = "format_version: 1\nmethod_name: voxel-grid\nconfig: {}\n" + 'a: &a ["x","x","x","x","x","x","x","x","x"]\n' + "".join(
    f"{n}: &{n} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, n in zip("abcdefgh", "bcdefghi"))


def make_capture_cases(seed: int = 0) -> list[CaptureCase]:
    """Every case of the suite, in a fixed order (the same for a seed)."""
    from nerf2gs_bench.fault_models import ENHANCERS, SEGMENTERS

    rng = random.Random(seed)
    C = CaptureCase
    photos = [f"f{i:03d}.png" for i in range(NUM_PHOTOS)]
    cases: list[CaptureCase] = []
    # process images: broken photos, a kill, two runs at once, new photos under the old names
    for kind in ("flip", "flip", "flip", "truncate", "truncate", "empty", "junk"):
        cases.append(C("process images", kind, rng.choice(photos)))
    cases += [C("process images", "kill -9", "mid-run", {"delay": d}) for d in (3.0, 7.0)]
    cases += [C("process images", "concurrent", "--out", {"stagger": s}) for s in (0.0, 0.5)]
    cases.append(C("process images", "changed content", "every photo"))
    cases.append(C("process images", "disk fills", "during the SfM", {"limit": 256_000}))
    # process video
    for kind in ("flip", "flip", "flip", "truncate", "truncate", "empty", "junk"):
        cases.append(C("process video", kind, "drive.avi"))
    cases.append(C("process video", "kill -9", "mid-run", {"delay": 4.0}))
    cases += [C("process video", "bad flag", flag, {"extra": [flag, v]}) for flag, v in (("--num-frames", "0"), ("--num-frames", "-5"), ("--fps", "-1"))]
    # masks onnx: broken model files, bad outputs, broken dataset files, a kill, two at once
    for what, kind in (("model", "flip"), ("model", "flip"), ("model", "truncate"), ("model", "junk"), ("image", "flip"),
                       ("image", "truncate"), ("transforms.json", "truncate"), ("transforms.json", "flip")):
        cases.append(C("masks onnx", kind, what))
    cases += [C("masks onnx", "bad model", name, {"model": f"segment_{name}"}) for name in SEGMENTERS]
    cases.append(C("masks onnx", "kill -9", "mid-run", {"delay": 3.0}))
    cases.append(C("masks onnx", "concurrent", "masks/"))
    # masks auto (the reference is the suite's trained run)
    for what, kind in (("model", "flip"), ("model", "truncate"), ("config.yml", "flip"), ("image", "truncate"), ("transforms.json", "flip")):
        cases.append(C("masks auto", kind, what))
    cases.append(C("masks auto", "kill -9", "mid-run", {"delay": 4.0}))
    # enhance apply
    cases += [C("enhance apply", "bad model", name, {"model": f"enhance_{name}"}) for name in ENHANCERS]
    cases.append(C("enhance apply", "bad model", "nan (other folder)", {"model": "enhance_nan", "in_place": False}))
    for what, kind in (("model", "flip"), ("model", "truncate"), ("model", "junk"), ("image", "flip"), ("image", "truncate"), ("image", "empty")):
        cases.append(C("enhance apply", kind, what))
    cases.append(C("enhance apply", "kill -9", "mid-run", {"delay": 2.5, "n": NUM_PHOTOS, "in_place": False}))
    cases.append(C("enhance apply", "concurrent", "output folder", {"in_place": False}))
    # eval
    for what, kind in (("checkpoint", "flip"), ("checkpoint", "flip"), ("checkpoint", "flip"), ("checkpoint", "truncate"),
                       ("checkpoint", "truncate"), ("config.yml", "flip"), ("config.yml", "truncate"), ("image", "flip"),
                       ("image", "truncate"), ("transforms.json", "flip"), ("dataparser_transforms.json", "truncate")):
        cases.append(C("eval", kind, what))
    cases.append(C("eval", "cut at a line", "config.yml"))
    cases.append(C("eval", "bad config", "alias bomb", {"text": ALIAS_BOMB}))
    cases.append(C("eval", "bad flag", "--max-images 0", {"extra": ["--max-images", "0"]}))
    cases.append(C("eval", "bad flag", "--max-images -3", {"extra": ["--max-images", "-3"]}))
    cases += [C("eval", "kill -9", "mid-run", {"delay": d}) for d in (2.0, 4.0)]
    cases.append(C("eval", "concurrent", "eval.json"))
    return cases


# the CI subset: one case of each kind of fault per entry point where it is quick
CI_SUBSET = [("enhance apply", "bad model"), ("enhance apply", "flip"), ("enhance apply", "kill -9"), ("masks onnx", "bad model"),
             ("masks onnx", "truncate"), ("eval", "flip"), ("eval", "cut at a line"), ("eval", "bad flag"), ("eval", "bad config"), ("eval", "kill -9"),
             ("process video", "junk")]


def ci_cases(seed: int = 0) -> list[CaptureCase]:
    """The first case of each (entry, fault) pair in :data:`CI_SUBSET`."""
    seen, out = set(), []
    for c in make_capture_cases(seed):
        key = (c.entry, c.fault)
        if key in CI_SUBSET and key not in seen:
            seen.add(key)
            out.append(c)
    return out


def run_capture_case(case: CaptureCase, fx: Fixtures, scratch: Path, seed: int, index: int = 0) -> CaptureResult:
    """``index``: the case's place in the suite (cases alike in all but it break other bytes)."""
    shutil.rmtree(scratch, ignore_errors=True)
    scratch.mkdir(parents=True)
    rng = random.Random(f"{seed}-{index}-{case.entry}-{case.fault}-{case.what}-{json.dumps(case.params, sort_keys=True)}")
    t0 = time.perf_counter()
    try:
        outcome, detail = RUNNERS[case.entry](case, fx, scratch, rng)
    except Exception as e:  # noqa: BLE001 - a failure of the checks themselves (e.g. a result that cannot be read)
        outcome, detail = "wrong_result", f"check failed: {type(e).__name__}: {str(e)[:200]}"
    return CaptureResult(case, outcome, detail[:400], round(time.perf_counter() - t0, 2))


def run_capture_suite(work: Path, seed: int = 0, cases: Optional[list[CaptureCase]] = None,
                      log: Optional[Callable[[str], None]] = None) -> dict[str, Any]:
    """Every case (or ``cases``); the summary per entry point and every case."""
    work = Path(work)
    fx = make_fixtures(work / "fixtures")
    cases = make_capture_cases(seed) if cases is None else cases
    results = []
    for i, c in enumerate(cases):
        r = run_capture_case(c, fx, work / "scratch", seed, i)
        results.append(r)
        if log:
            log(f"[{i + 1}/{len(cases)}] {c.entry} / {c.fault} / {c.what}: {r.outcome} ({r.seconds:.1f} s) {r.detail[:160]}")
    return {"summary": summarize_capture(results), "cases": [dataclasses.asdict(r) for r in results]}


def summarize_capture(results: list[CaptureResult]) -> dict[str, Any]:
    def counts(rs: list[CaptureResult]) -> dict[str, int]:
        return {"cases": len(rs), **{k: sum(r.outcome == k for r in rs) for k in OUTCOMES}}

    entries = sorted({r.case.entry for r in results})
    return {**counts(results), "by_entry": {e: counts([r for r in results if r.case.entry == e]) for e in entries},
            "max_case_seconds": max((r.seconds for r in results), default=0.0)}
