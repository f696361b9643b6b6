"""The bench's own modules import only downward and never around a loop: shared helpers, the run keys,
the runner, the benches, the CLI on top (a bench may use another bench's tables)."""

from __future__ import annotations

from pathlib import Path

from test_import_layers import _cycles, imports_of

BENCH = "nerf2gs_bench"
ROOT = Path(__file__).resolve().parents[2] / BENCH

LAYERS: list[tuple[str, ...]] = [
    ("", "machine", "code_version", "stage_record", "perturb", "breaking_point", "stability_levels", "fault_models", "step_ab",
     "hand_labels", "mover_kinds"),
    ("runs",),  # run specs, keys and reuse of trained runs
    ("runner",),  # training, evaluating and writing a bench's results
    ("paper", "speed_quality", "size", "stability", "raster", "field", "faults", "faults_capture", "real", "real_photos", "scale",
     "capture_truth", "capture_compare",
     "blocks", "enhancer", "demo", "plans", "motion_product", "render_fps", "paper_scale_real"),  # plans: the validation studies' runner
    ("real_captures", "real_path_speed"),  # each capture through the real-photos bench; the path timed (on a capture too)
    ("street_level",),  # levers of the augmentation on the real captures' runs
    ("cli",),
]
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}


def _graph() -> dict[str, set[str]]:
    modules = {(BENCH + "." + p.stem if p.stem != "__init__" else BENCH): p for p in sorted(ROOT.glob("*.py"))}
    return {name: imports_of(name, path, modules, package=BENCH) for name, path in modules.items()}


def _layer(module: str) -> int:
    return RANK[module.split(".")[1] if "." in module else ""]


def test_every_bench_module_has_a_layer():
    unknown = sorted({m.split(".")[1] for m in _graph() if "." in m} - set(RANK))
    assert not unknown, f"add these to LAYERS: {unknown}"


def test_bench_imports_only_go_down_and_never_around_a_loop():
    graph = _graph()
    upward = sorted((a, b) for a, bs in graph.items() for b in bs if _layer(b) > _layer(a))
    assert not upward, f"bench imports that go up a layer: {upward}"
    assert not _cycles(graph), f"bench import cycles: {_cycles(graph)}"
