"""make demo's output: readable links per run under outputs/demo, the next commands with real
paths; runs record their dataset absolutely and old relative records are still found."""

from __future__ import annotations

import os
from pathlib import Path

from nerf2gs_plugin.runs.load import find_dataset
from nerf2gs_bench.demo import link_runs, next_steps, readable_name


def test_readable_names():
    assert readable_name("splatfacto + NeRF views") == "splatfacto+nerf-views"
    assert readable_name("StreetNeRF") == "streetnerf"
    assert readable_name("Scaffold-GS + NeRF views + enhancer") == "scaffold-gs+nerf-views+enhancer"


def test_links_and_next_commands(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    root = Path("outputs/demo")
    runs = {}
    for label, method, key in (("StreetNeRF", "streetnerf", "a1"), ("splatfacto", "splatfacto", "b2"),
                               ("splatfacto + NeRF views", "splatfacto", "c3")):
        d = root / "runs" / "street" / method / key
        (d / "checkpoints").mkdir(parents=True)
        runs[label] = {"label": label, "run_dir": str(d)}
    runs["broken"] = {"label": "broken", "failed": True}
    links = link_runs(runs, root)
    assert sorted(p.name for p in links.values()) == ["splatfacto", "splatfacto+nerf-views", "streetnerf"]
    assert (root / "splatfacto+nerf-views").resolve() == (root / "runs/street/splatfacto/c3").resolve()
    assert not os.path.isabs(os.readlink(root / "streetnerf"))  # relative: the folder can move
    link_runs(runs, root)  # a second demo replaces the links
    text = next_steps(links, root / "quick.md", Path("data/street"))
    assert "ns2gs-viewer outputs/demo/splatfacto+nerf-views" in text
    assert "ns2gs-export outputs/demo/splatfacto+nerf-views --format ply" in text
    assert "--augment-from outputs/demo/streetnerf" in text and "outputs/demo/quick.md" in text


def test_relative_dataset_found_from_elsewhere(tmp_path, monkeypatch):
    repo = tmp_path / "repo"
    (repo / "benchmarks/runs/data/street").mkdir(parents=True)
    run_dir = repo / "benchmarks/runs/street/splatfacto/abc"
    run_dir.mkdir(parents=True)
    monkeypatch.chdir(tmp_path)  # not the repo: the recorded relative path does not exist from here
    found = find_dataset(Path("benchmarks/runs/data/street"), run_dir)
    assert found == repo / "benchmarks/runs/data/street"
    assert find_dataset(Path("/abs/elsewhere"), run_dir) == Path("/abs/elsewhere")


def test_trainer_records_the_dataset_absolutely(tmp_path, monkeypatch):
    import dataclasses

    from nerf2gs_plugin.engine.trainer import Trainer
    from nerf2gs_plugin.methods.splatfacto.config import splatfacto_method

    monkeypatch.chdir(tmp_path)
    trainer = Trainer(dataclasses.replace(splatfacto_method.config, data=Path("data/street")))
    assert trainer.config.data == tmp_path / "data/street"
