"""What the stability, model-size and speed-quality benches share: a run-and-evaluate step that
records failures instead of aborting the bench, a log file per bench, and the JSON + Markdown
output with the machine line."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

from nerf2gs_plugin.errors import UserError
from nerf2gs_bench.runs import IN_USE, RunSpec, evaluation_lock, run_key, train_or_reuse
from nerf2gs_bench.machine import machine_info, machine_line
from nerf2gs_plugin.utils.lpips import LPIPS
from nerf2gs_plugin.utils.config import apply_plain
from nerf2gs_plugin.utils.io import atomic_write_text

EVAL_SPLITS = ("street", "bev_1", "bev_2", "lane_1", "lane_2", "lane_4")  # a dataset's missing ones are skipped
VAL_SPLITS = ("val_street", "val_bev", "val_lane")  # the synthetic street's validation views: choose defaults on these


def eval_cache_name(splits: tuple[str, ...]) -> str:
    """The file in a run folder that caches the bench's evaluation of ``splits``."""
    return "bench_eval.json" if tuple(splits) == EVAL_SPLITS else f"bench_eval_{'-'.join(splits)}.json"


class BenchFailed(UserError):
    """Some runs of a bench failed; the results (failed rows included) are written already."""


def fmt(value: Optional[float], digits: int = 2) -> str:
    """A table cell: 'n/a' for missing or non-finite values, never a made-up number."""
    if value is None or not isinstance(value, (int, float)) or not math.isfinite(value):
        return "n/a"
    return f"{value:.{digits}f}"


def mean_psnr(result: dict, splits: tuple[str, ...]) -> Optional[float]:
    """Mean PSNR over those of ``splits`` the result has (None when it has none)."""
    vals = [result.get("results", {}).get(s, {}).get("psnr") for s in splits]
    vals = [v for v in vals if isinstance(v, (int, float))]
    return sum(vals) / len(vals) if vals else None


def write_bench_files(out_dir: Path, name: str, title: str, payload: dict, md_body: str,
                      machine: Optional[dict] = None) -> str:
    """``<name>.json`` (payload + machine) and ``<name>.md`` (title, machine line, body)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    info = machine or machine_info()
    md = f"# {title}\n\nMachine: {machine_line(info)}\n\n{md_body.rstrip()}\n"
    atomic_write_text(out_dir / f"{name}.json", json.dumps({"title": title, "machine": info, **payload}, indent=1, default=str))
    atomic_write_text(out_dir / f"{name}.md", md)
    return md


class BenchLog:
    """Prints and appends to ``<runs_root>/logs/<bench>.log`` (kept across runs of the bench)."""

    def __init__(self, runs_root: Path, bench: str, echo: Callable[[str], None] = print) -> None:
        self.path = Path(runs_root) / "logs" / f"{bench}.log"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.echo = echo

    def __call__(self, line: str) -> None:
        with open(self.path, "a") as f:
            f.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {line}\n")
        self.echo(line)


@dataclass
class Outcome:
    """One run of a bench: its eval result, or the error that stopped it."""

    label: str
    result: Optional[dict] = None
    error: Optional[str] = None
    run_dir: Optional[str] = None
    key: Optional[str] = None  # the run's cache key (a later run's reference)


def nonfinite_metrics(result: Optional[dict]) -> bool:
    """True when some split's PSNR or SSIM is missing or not finite (a NaN model)."""
    if result is None:
        return True
    values = [r.get(k) for r in result.get("results", {}).values() for k in ("psnr", "ssim")]
    return any(not isinstance(v, (int, float)) or not math.isfinite(v) for v in values)


def failure_reason(outcome: Outcome) -> Optional[str]:
    """Why a bench run counts as failed (its error, or non-finite metrics); None when it did not."""
    if outcome.error is not None:
        return outcome.error
    if nonfinite_metrics(outcome.result):
        return "nan: non-finite PSNR/SSIM"
    return None


class BenchRunner:
    """Train-or-reuse then evaluate; any error in training or evaluation (NaN/inf divergence, bad
    data, a runtime error) becomes an :class:`Outcome` with ``error`` set, and the bench goes on.

    The evaluation is cached in ``bench_eval.json`` under :func:`eval_key` (the run key, the metric
    code's hash, the splits and the device), so a changed metric or another device re-evaluates;
    FPS and times in a result carry ``measured`` / ``trained`` labels (machine, date, device).
    Deterministic failures (user errors, divergence) are remembered under the run key, so they
    expire when the code, data or config change; others are retried. ``rerun=True`` retrains and
    re-evaluates every run once, ignoring failure markers. ``splits``: the eval splits (the test
    views by default; :data:`VAL_SPLITS` to choose a default)."""

    def __init__(self, runs_root: Path, log: Callable[[str], None] = print, device: str = "auto", rerun: bool = False,
                 splits: tuple[str, ...] = EVAL_SPLITS) -> None:
        from nerf2gs_plugin.engine.trainer import pick_device

        self.runs_root = Path(runs_root)
        self.log = log
        self.device = pick_device(device)
        self.rerun = rerun
        self.splits = tuple(splits)
        self._rerun_done: set[str] = set()
        self._lpips: Any = None
        self._fingerprints: dict[str, str] = {}

    def key(self, spec: RunSpec, data: Path, reference: Optional[tuple[Path, str]] = None) -> str:
        """The run key this runner trains ``spec`` under (see :func:`~nerf2gs_bench.runs.run_key`)."""
        from nerf2gs_bench.code_version import device_label

        return run_key(self.fingerprint(data), spec, reference[1] if reference else None, device_label(self.device))

    def eval_key(self, run_key_: str) -> str:
        """What a cached evaluation must match: the run, the metric code, the splits, the device."""
        import hashlib

        from nerf2gs_bench.code_version import device_label, eval_code_hash

        doc = json.dumps([run_key_, eval_code_hash(), list(self.splits), device_label(self.device)])
        return hashlib.sha1(doc.encode()).hexdigest()[:12]

    def fingerprint(self, data: Path) -> str:
        from nerf2gs_plugin.data import folder_fingerprint

        key = str(Path(data).resolve())
        if key not in self._fingerprints:
            self._fingerprints[key] = folder_fingerprint(data)
        return self._fingerprints[key]

    def lpips(self):
        if self._lpips is None:
            self._lpips = LPIPS.load_default(device=self.device) or False
        return self._lpips or None

    def run(self, spec: RunSpec, data: Path, reference: Optional[tuple[Path, str]] = None, step_hook=None) -> Outcome:
        from nerf2gs_plugin.runs.load import load_run
        from nerf2gs_plugin.eval.evaluate import evaluate_run

        key = self.key(spec, data, reference)
        rerun = self.rerun and key not in self._rerun_done
        self._rerun_done.add(key)
        # keyed by the run key, which holds the code hash: a marker expires when the code changes
        marker = self.runs_root / "failures" / f"{Path(data).name}-{spec.method}-{key}.json"
        if marker.is_file() and not rerun:  # a failed run fails again the same way: do not retrain it on every rerun
            error = json.loads(marker.read_text())["error"]
            self.log(f"[bench] {spec.label}: known failure ({error}); delete {marker} or pass --rerun to retry")
            return Outcome(spec.label, error=error, key=key)
        marker.unlink(missing_ok=True)
        try:
            run_dir, _ = train_or_reuse(spec, data, self.runs_root, self.fingerprint(data), reference=reference,
                                        progress=False, log=self.log, step_hook=step_hook, device=str(self.device),
                                        rerun=rerun)
            res = self._evaluate(run_dir, key, load_run, evaluate_run)
        except Exception as e:  # noqa: BLE001 - one failed run must not stop a bench of many
            msg = str(e).splitlines()[0][:300] if str(e) else type(e).__name__
            error = f"{type(e).__name__}: {msg}"
            self.log(f"[bench] {spec.label} FAILED: {error}")
            if isinstance(e, (UserError, FloatingPointError)) and IN_USE not in str(e):  # a busy lock is not the run's fault
                marker.parent.mkdir(parents=True, exist_ok=True)
                atomic_write_text(marker, json.dumps({"label": spec.label, "error": error}))
            return Outcome(spec.label, error=error, key=key)
        res.update(label=spec.label, target=spec.method, run_dir=str(run_dir))
        return Outcome(spec.label, result=res, run_dir=str(run_dir), key=key)

    def _evaluate(self, run_dir: Path, key: str, load_run, evaluate_run) -> dict:
        """The cached evaluation when its :meth:`eval_key` matches, else a fresh one (labelled)."""
        from nerf2gs_bench.code_version import device_label

        eval_path = run_dir / eval_cache_name(self.splits)  # validation and test evaluations cached side by side
        want = self.eval_key(key)
        with evaluation_lock(run_dir):  # read after the lock: another bench may just have written it
            res = json.loads(eval_path.read_text()) if eval_path.is_file() else None
            if res is None or res.get("eval_key") != want:
                run = load_run(run_dir, device=self.device)
                names = [s for s in self.splits if s in run.pipeline.datamanager.eval_split_names()]
                if not names and self.splits != EVAL_SPLITS:
                    return {"results": {}}  # asked for splits (validation views) this dataset does not have
                names = names or None
                t0 = time.perf_counter()
                res = evaluate_run(run, names, render_dir=run_dir / "eval_renders", lpips_model=self.lpips())
                res["eval_key"] = want
                res["measured"] = {"machine": machine_line(), "device": device_label(self.device),
                                   "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                   "seconds": round(time.perf_counter() - t0, 3)}
                atomic_write_text(eval_path, json.dumps(res, indent=1))
        trained = run_dir / "bench_run.json"
        if trained.is_file():
            res["trained"] = json.loads(trained.read_text()).get("trained")
        return res


def progress_log(progress, log_file: BenchLog) -> Callable[[str], None]:
    """Log lines printed above a running rich progress bar."""

    def echo(line: str) -> None:
        progress.console.print(line, markup=False, highlight=False, soft_wrap=True)  # a long path stays on its line

    log_file.echo = echo
    return log_file


def planned_steps(method: str, overrides: dict, augment: Optional[dict] = None) -> int:
    """Training steps of a run: its method's config with the overrides applied (``augment``: the
    ``--augment.*`` of a run trained with NeRF views, whose step factor lengthens it)."""
    from nerf2gs_plugin.engine.trainer import augmented_steps
    from nerf2gs_plugin.registry import get_method

    config = apply_plain(get_method(method).config, overrides, where=f"bench run of {method}")
    if augment is not None:
        config = apply_plain(config, {"augment_from": "reference", "augment": augment}, where=f"bench run of {method}")
    return int(augmented_steps(config))


class BenchProgress:
    """One bar over a whole bench, counted in training steps (reused runs jump ahead at once);
    the runs' own bars are off, and their step hook moves this one."""

    def __init__(self, progress, name: str, steps: list[int]) -> None:
        self.progress, self.steps = progress, list(steps)
        self.task = progress.add_task(name, total=max(1, sum(self.steps)), stats="")
        self.base = 0

    def start(self, index: int, label: str) -> None:
        self.base = sum(self.steps[:index])
        self.progress.update(self.task, completed=self.base, stats=f"({index + 1}/{len(self.steps)}) {label}")

    def hook(self, step: int) -> None:
        self.progress.update(self.task, completed=self.base + step + 1)

    def finish(self, index: int) -> None:
        self.progress.update(self.task, completed=sum(self.steps[: index + 1]))
