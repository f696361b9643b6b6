"""Benches cannot serve stale results: the run key holds the model code's hash and the device, the
cached evaluation the metric code's hash, the dataset fingerprint every file a run reads, and
``--rerun`` retrains. The code is changed in a temporary copy of the package (the hashed source
root is pointed at it), one line of a loss at a time."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from nerf2gs_bench import code_version, runs as bench_runs
from nerf2gs_bench.runs import RunSpec


@pytest.fixture
def source_copy(tmp_path, monkeypatch) -> Path:
    """A private copy of the package source that the code hashes read."""
    dst = tmp_path / "src" / "nerf2gs_plugin"
    shutil.copytree(code_version.SOURCE_ROOT, dst, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(code_version, "SOURCE_ROOT", dst)
    return dst


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, f"{path} no longer has {old!r}"
    path.write_text(text.replace(old, new, 1))


def test_model_files_rule():
    names = {str(p.relative_to(code_version.SOURCE_ROOT)) for p in code_version.model_source_files()}
    assert "engine/losses.py" in names and "methods/splatfacto/model.py" in names
    assert any(n.endswith(".cpp") for n in names)  # the kernels count
    assert not any(n.split("/")[0] in ("eval", "cli", "viewer", "masking") for n in names)
    assert "masks/from_renders.py" in names  # the augmentation reads the reference's sky with it
    assert not any(n.startswith(("data/process/",)) for n in names)
    assert "data/ground.py" in names and "data/colmap_parser.py" in names  # parsers read it
    assert "utils/image_metrics.py" in names and "utils/lpips.py" in names  # the enhancer selects by them


def test_no_model_code_imports_the_folders_left_out_of_the_hash():
    """The exclusion is only sound while model code never imports the dataset makers."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from test_import_layers import import_graph

    def folder(module: str) -> str | None:
        rel = "/".join(module.split(".")[1:])
        return next((f for f in code_version.NOT_MODEL_CODE if rel == f or rel.startswith(f + "/")), None)

    arrows = sorted((a, b) for a, bs in import_graph().items() for b in bs
                    if folder(a) is None and folder(b) is not None)
    assert not arrows, f"model code imports code left out of the model hash: {arrows}"


def test_run_key_changes_with_one_line_of_a_loss_and_with_the_device(source_copy):
    spec = RunSpec("sf", "splatfacto", {"max_num_iterations": 50})
    k0 = bench_runs.run_key("data", spec, None, "cpu")
    assert bench_runs.run_key("data", spec, None, "cpu") == k0
    assert bench_runs.run_key("data", spec, None, "cuda:NVIDIA H100") != k0
    e0 = code_version.eval_code_hash()
    _edit(source_copy / "eval" / "table_print.py", "\n", "\n# a table tweak: models do not change\n")
    assert bench_runs.run_key("data", spec, None, "cpu") == k0
    _edit(source_copy / "engine" / "losses.py", "\n", "\n# one changed line\n")
    k1 = bench_runs.run_key("data", spec, None, "cpu")
    assert k1 != k0
    assert code_version.eval_code_hash() == e0
    _edit(source_copy / "eval" / "evaluate.py", "\n", "\n# a metric fix\n")
    assert code_version.eval_code_hash() != e0 and bench_runs.run_key("data", spec, None, "cpu") == k1


def test_bench_retrains_after_a_loss_change_reevaluates_after_a_metric_change_and_reruns(tiny_scene, tmp_path, source_copy,
                                                                                        monkeypatch):
    from nerf2gs_plugin.utils import lpips as lpips_mod
    from nerf2gs_bench.runner import BenchRunner

    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)  # fast: LPIPS n/a
    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    lines: list[str] = []
    runner = lambda **kw: BenchRunner(tmp_path / "runs", log=lines.append, device="cpu", **kw)  # noqa: E731
    spec = RunSpec("vox", "voxel-grid", {"max_num_iterations": 6, "steps_per_save": 6, "steps_per_eval_image": 0,
                                         "pipeline": {"model": {"resolution": 8, "num_samples": 4}}})
    first = runner().run(spec, tiny_scene)
    assert first.error is None and any(line.startswith("[bench] train vox") for line in lines)
    res = first.result
    assert res["measured"]["device"] == "cpu" and "cores" in res["measured"]["machine"] and res["measured"]["date"][:2] == "20"
    assert res["trained"]["device"] == "cpu" and res["trained"]["date"][:2] == "20" and "cores" in res["trained"]["machine"]
    lines.clear()
    again = runner().run(spec, tiny_scene)
    assert again.key == first.key and any(line.startswith("[bench] reuse vox") for line in lines)
    assert again.result["measured"] == res["measured"]  # cached evaluation served
    # the run's own seconds travel with it: a reuse reports what training and evaluation took, not ~0 s
    assert res["trained"]["seconds"] > 0 and res["measured"]["seconds"] > 0
    assert again.result["trained"]["seconds"] == res["trained"]["seconds"]

    _edit(source_copy / "eval" / "evaluate.py", "\n", "\n# a metric fix\n")
    lines.clear()
    reeval = runner().run(spec, tiny_scene)
    assert reeval.key == first.key and any(line.startswith("[bench] reuse vox") for line in lines)
    assert json.loads((Path(reeval.run_dir) / "bench_eval.json").read_text())["eval_key"] != res["eval_key"]

    _edit(source_copy / "engine" / "losses.py", "\n", "\n# one changed line of a loss\n")
    lines.clear()
    changed = runner().run(spec, tiny_scene)
    assert changed.key != first.key and any(line.startswith("[bench] train vox") for line in lines)

    lines.clear()
    fresh = runner(rerun=True).run(spec, tiny_scene)  # trained by this process already: fresh, not again
    assert fresh.key == changed.key and any(line.startswith("[bench] reuse vox") for line in lines)
    assert not any("--rerun" in line for line in lines)

    monkeypatch.setattr(bench_runs, "_TRAINED_HERE", set())  # another invocation
    lines.clear()
    forced = runner(rerun=True).run(spec, tiny_scene)
    assert forced.key == changed.key and any("--rerun" in line for line in lines)
    assert any(line.startswith("[bench] train vox") for line in lines)


def test_failure_markers_expire_with_the_code(tiny_scene, tmp_path, source_copy):
    from nerf2gs_bench.runner import BenchRunner

    lines: list[str] = []
    runner = BenchRunner(tmp_path / "runs", log=lines.append, device="cpu")
    spec = RunSpec("vox", "voxel-grid", {"max_num_iterations": 4})
    key = runner.key(spec, tiny_scene)
    marker = tmp_path / "runs" / "failures" / f"{tiny_scene.name}-voxel-grid-{key}.json"
    marker.parent.mkdir(parents=True)
    marker.write_text(json.dumps({"label": "vox", "error": "TrainingDiverged: old"}))
    assert runner.run(spec, tiny_scene).error == "TrainingDiverged: old"
    _edit(source_copy / "engine" / "losses.py", "\n", "\n# the fix\n")
    assert runner.key(spec, tiny_scene) != key  # the old marker no longer matches: the run is retried


def test_dataset_fingerprint_covers_every_file_a_run_reads(tiny_scene, tmp_path):
    from nerf2gs_plugin.data import dataset_files, folder_fingerprint

    data = tmp_path / "scene"
    shutil.copytree(tiny_scene, data, ignore=shutil.ignore_patterns(".ns2gs_cache"))
    names = {str(p.relative_to(data)) for p in dataset_files(data)}
    assert {"transforms.json", "points.ply"} <= names
    assert any(n.startswith("masks/transient/") for n in names)
    meta = json.loads((data / "transforms.json").read_text())
    eval_image = next(iter(meta["eval_splits"].values()))[0]["file_path"]
    assert eval_image in names
    f0 = folder_fingerprint(data)
    moved = tmp_path / "moved"
    shutil.copytree(data, moved)
    assert folder_fingerprint(moved) == f0
    (data / "notes.txt").write_text("not read by a run")
    assert folder_fingerprint(data) == f0
    seen = {f0}
    for rel in (next(n for n in names if n.startswith("masks/sky/")), eval_image, "points.ply"):
        p = data / rel
        p.write_bytes(p.read_bytes() + b"\0")
        seen.add(folder_fingerprint(data))
    meta["frames"][0]["transform_matrix"][0][3] += 0.01  # a pose
    (data / "transforms.json").write_text(json.dumps(meta))
    seen.add(folder_fingerprint(data))
    assert len(seen) == 5


def test_bench_regenerates_a_street_of_an_older_generator(tmp_path, monkeypatch):
    from nerf2gs_bench import cli as bench
    from nerf2gs_plugin.data import synthetic_street

    made = []
    monkeypatch.setattr(synthetic_street, "generate_street", lambda cfg: made.append(cfg))
    street = tmp_path / "data" / "street"
    street.mkdir(parents=True)
    (street / "transforms.json").write_text(json.dumps({"synthetic_street": {"generator_version": 1}, "frames": []}))
    assert bench.ensure_street(None, tmp_path) == street
    assert len(made) == 1 and made[0].overwrite
    (street / "transforms.json").write_text(json.dumps({"synthetic_street": {"generator_version": synthetic_street.GENERATOR_VERSION}}))
    bench.ensure_street(None, tmp_path)
    assert len(made) == 1


def test_a_bench_waits_for_another_training_of_the_same_run(tmp_path):
    """Two benches sharing a runs folder: the second waits for the first's training of a run (and
    then reuses it) instead of failing on the run directory's lock and caching that as a failure."""
    import threading
    import time

    from nerf2gs_plugin.engine.run_dir import RunDirLock
    from nerf2gs_bench.runs import wait_for_other_training

    wait_for_other_training(tmp_path / "never-trained")  # no lock file: returns at once
    lock = RunDirLock(tmp_path / "run")
    lock.acquire()
    threading.Timer(0.5, lock.release).start()
    said: list[str] = []
    t0 = time.monotonic()
    wait_for_other_training(tmp_path / "run", log=said.append)
    assert time.monotonic() - t0 >= 0.4
    assert said and "waiting for another process" in said[0]
    wait_for_other_training(tmp_path / "run", log=said.append)  # free now: no wait, nothing said
    assert len(said) == 1


def test_two_benches_evaluate_a_shared_run_once(tmp_path):
    """Two benches reaching the same finished run at once: one evaluates it, the other waits and reads
    its cached result (both used to write the same render files, and one failed on the other's temp file)."""
    import threading
    import time
    from types import SimpleNamespace

    from nerf2gs_bench.runner import BenchRunner

    run_dir = tmp_path / "run"
    run_dir.mkdir()
    calls: list[int] = []

    def load_run(path, device=None):
        return SimpleNamespace(pipeline=SimpleNamespace(datamanager=SimpleNamespace(eval_split_names=lambda: ["street"])))

    def evaluate_run(run, names, render_dir=None, lpips_model=None):
        calls.append(1)
        time.sleep(0.3)  # long enough for the other bench to arrive meanwhile
        return {"results": {"street": {"psnr": 20.0 + len(calls)}}}

    runners = [BenchRunner(tmp_path / "runs"), BenchRunner(tmp_path / "runs")]
    for r in runners:
        r._lpips = False  # no LPIPS weights needed
    got: list[dict] = []
    threads = [threading.Thread(target=lambda r=r: got.append(r._evaluate(run_dir, "k", load_run, evaluate_run))) for r in runners]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1 and [g["results"] for g in got] == [{"street": {"psnr": 21.0}}] * 2


def test_a_bench_that_loses_the_race_for_a_run_waits_and_reuses_it(tmp_path, monkeypatch):
    """The other bench takes a run's lock between this bench's wait and its trainer's setup: the lock error is
    not the run's failure (a bench would remember it and report the run as failed): wait, then reuse the run."""
    from nerf2gs_plugin.engine.run_dir import RunDirLock
    from nerf2gs_plugin.errors import ConfigError

    held = RunDirLock(tmp_path / "x")
    held.acquire()
    with pytest.raises(ConfigError) as e:
        RunDirLock(tmp_path / "x").acquire()
    held.release()
    assert bench_runs.IN_USE in str(e.value)  # the message the bench recognises is the lock's own

    finished = {"now": False}

    class OtherHasIt:
        def __init__(self, cfg):
            self.cfg = cfg

        def setup(self):
            finished["now"] = True  # by the time this bench has waited, the other bench has finished the run
            raise ConfigError(f"{bench_runs.IN_USE} (pid 1); choose another --timestamp or --run-dir", tmp_path)

    monkeypatch.setattr(bench_runs, "Trainer", OtherHasIt)
    monkeypatch.setattr(bench_runs, "list_checkpoints", lambda d: [Path(d) / "step-9.ckpt"] if finished["now"] else [])
    monkeypatch.setattr(bench_runs, "load_checkpoint", lambda p: {"step": 10 ** 9})
    said: list[str] = []
    run_dir, key = bench_runs.train_or_reuse(RunSpec("s", "splatfacto", {}), tmp_path / "data", tmp_path / "runs", "fp", log=said.append)
    assert any("waiting to reuse it" in s for s in said) and any(s.startswith("[bench] reuse s:") for s in said)
    assert run_dir.parent.parent.parent == tmp_path / "runs" and run_dir.name == key

    class Broken(OtherHasIt):
        def setup(self):
            raise ConfigError("some other mistake", tmp_path)

    finished["now"] = False
    monkeypatch.setattr(bench_runs, "Trainer", Broken)
    with pytest.raises(ConfigError, match="some other mistake"):  # any other error is the run's own
        bench_runs.train_or_reuse(RunSpec("s", "splatfacto", {}), tmp_path / "data", tmp_path / "runs", "fp", log=said.append)
