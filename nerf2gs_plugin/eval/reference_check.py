"""Is the reference worth inheriting? Its measured held-out PSNR against the target's baseline.

Before a target trains on a reference's views (``--augment-from``), say in the
run's log, with the measured numbers, whether the reference is weaker than the target trained
without it. The numbers are the ones already measured in each run folder (``eval.json`` from
``ns2gs-eval``, or a bench's ``bench_eval*.json``), never recomputed here: this runs before
training and must cost nothing. Only the street-level held-out split both runs were evaluated on
counts (``test``: the held-out photos of a capture; ``street`` on the synthetic streets), and only
when both saw the same number of views.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Optional, Union

from nerf2gs_plugin.utils.io import atomic_write_text

HELD_OUT_SPLITS = ("test", "street", "val")
"""Street-level held-out splits, in order of preference (a capture's held-out photos first)."""
CHECK_FILE = "reference_check.json"
"""Written into the target's run folder."""


def _run_dir(path: Path) -> Path:
    path = Path(path)
    return path.parent if path.suffix == ".ckpt" else path


def measured_eval(run: Path) -> Optional[dict]:
    """The newest evaluation stored in a run folder (``eval.json`` or ``bench_eval*.json``), or None."""
    folder = _run_dir(run)
    found = []
    for p in [folder / "eval.json", *sorted(folder.glob("bench_eval*.json"))]:
        try:
            doc = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if isinstance(doc, dict) and isinstance(doc.get("results"), dict):
            found.append((p.stat().st_mtime, str(p), doc))
    if not found:
        return None
    _, path, doc = max(found)
    return {**doc, "eval_file": path}


def held_out(result: dict, split: Optional[str] = None) -> Optional[tuple[str, float, int]]:
    """(split, mean PSNR, views) of the preferred held-out split in an evaluation, or None."""
    res = result.get("results", {})
    for s in ([split] if split else HELD_OUT_SPLITS):
        r = res.get(s) or {}
        if r.get("psnr") is not None and r.get("num_images"):
            return s, float(r["psnr"]), int(r["num_images"])
    return None


@dataclass
class ReferenceCheck:
    """The reference's held-out PSNR against the baseline's, on the same split and views."""

    reference: str
    baseline: str
    split: str
    views: int
    reference_psnr: float
    baseline_psnr: float
    reference_ssim: Optional[float] = None
    baseline_ssim: Optional[float] = None

    @property
    def delta_db(self) -> float:
        """Reference minus baseline (negative: the reference is weaker)."""
        return self.reference_psnr - self.baseline_psnr

    @property
    def weaker(self) -> bool:
        return self.delta_db < 0

    def line(self) -> str:
        where = "BELOW" if self.weaker else "above"
        head = "reference is weaker than the target's baseline: " if self.weaker else "reference check: "
        tail = (" - its views may cost the target street quality (where street level matters more than the view "
                "from above, --augment.birds-eye-share 0.25 gives the input views more of the samples: "
                "docs/augmentation.md)" if self.weaker else "")
        return (f"{head}the reference is {abs(self.delta_db):.2f} dB {where} the baseline on {self.views} held-out views "
                f"({self.split}: reference {self.reference_psnr:.2f} dB vs baseline {self.baseline_psnr:.2f} dB PSNR; "
                f"reference {self.reference}, baseline {self.baseline}){tail}")

    def to_json(self) -> dict:
        return {**asdict(self), "delta_db": self.delta_db, "weaker": self.weaker, "line": self.line()}


def compare_runs(reference: Path, baseline: Path) -> Union[ReferenceCheck, str]:
    """The check of two runs' stored evaluations, or the one-line reason it cannot be made."""
    ref, base = measured_eval(reference), measured_eval(baseline)
    if ref is None:
        return f"reference {_run_dir(reference)} has no measured held-out metrics (run ns2gs-eval on it first)"
    if base is None:
        return f"baseline {_run_dir(baseline)} has no measured held-out metrics (run ns2gs-eval on it first)"
    r = held_out(ref)
    if r is None:
        return f"reference {_run_dir(reference)} was not evaluated on a held-out split ({', '.join(HELD_OUT_SPLITS)})"
    b = held_out(base, r[0])
    if b is None:
        return f"baseline {_run_dir(baseline)} was not evaluated on the reference's held-out split '{r[0]}'"
    if r[2] != b[2]:
        return f"reference and baseline were evaluated on different views ({r[2]} vs {b[2]} '{r[0]}' images)"
    ssim = [x.get("results", {}).get(r[0], {}).get("ssim") for x in (ref, base)]
    return ReferenceCheck(str(_run_dir(reference)), str(_run_dir(baseline)), r[0], r[2], r[1], b[1], ssim[0], ssim[1])


def reference_report(reference: Path, baseline: Optional[Path]) -> tuple[str, dict]:
    """(the log line, the JSON document) on the reference before the target trains on it. Without a
    baseline, the reference's own measured held-out PSNR (or that there is none)."""
    if baseline is not None:
        check = compare_runs(reference, baseline)
    else:
        ev = measured_eval(reference)
        h = held_out(ev) if ev else None
        check = (f"reference {_run_dir(reference)}: {h[1]:.2f} dB PSNR on {h[2]} held-out views ({h[0]}); "
                 "no baseline to compare with (--baseline RUN: the target trained without NeRF views)") if h else (
                 f"reference {_run_dir(reference)} has no measured held-out metrics (ns2gs-eval it) and no baseline was given")
    if isinstance(check, ReferenceCheck):
        return check.line(), check.to_json()
    line = f"reference check: {check}"
    return line, {"reference": str(_run_dir(reference)), "baseline": str(_run_dir(baseline)) if baseline else None, "line": line}


def report_text(doc: dict) -> str:
    """The JSON text of ``reference_check.json``."""
    return json.dumps(doc, indent=1)


def write_reference_report(run_dir: Path, doc: dict) -> Path:
    """``run_dir/reference_check.json`` (atomic)."""
    path = Path(run_dir) / CHECK_FILE
    atomic_write_text(path, report_text(doc))
    return path
