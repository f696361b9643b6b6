"""Stage seconds saved beside a stage's output: a rerun that reuses the output reports the saved
seconds (not the ~0 s of the reuse), and output made by other code is not reused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from nerf2gs_bench import code_version, real_photos as rp
from nerf2gs_bench.stage_record import read_stage, stage_key, write_stage


def test_a_record_is_read_back_only_under_its_key(tmp_path):
    path = tmp_path / "stage.json"
    assert read_stage(path, "k") is None  # absent
    write_stage(path, stage_key("a", 1), 12.34, extra={"x": 1})
    assert read_stage(path, stage_key("a", 1)) == {"key": stage_key("a", 1), "seconds": 12.3, "extra": {"x": 1}}
    assert read_stage(path, stage_key("a", 2)) is None  # made otherwise
    path.write_text("{not json")
    assert read_stage(path, stage_key("a", 1)) is None


def test_source_hash_follows_the_named_folders_only(tmp_path):
    root = tmp_path / "pkg"
    (root / "masks").mkdir(parents=True)
    (root / "engine").mkdir()
    (root / "masks" / "a.py").write_text("x = 1\n")
    (root / "engine" / "b.py").write_text("y = 1\n")
    h = code_version.source_hash(("masks",), root)
    (root / "engine" / "b.py").write_text("y = 2\n")
    assert code_version.source_hash(("masks",), root) == h
    (root / "masks" / "a.py").write_text("x = 2\n")
    assert code_version.source_hash(("masks",), root) != h
    assert code_version.source_hash(("masks/a.py",), root) != code_version.source_hash(("engine/b.py",), root)


class _Report:
    def __init__(self, out: Path) -> None:
        self.out, self.frames, self.registered, self.points, self.matching = out, 5, 4, 100, "exhaustive"
        self.metres_per_unit, self.scale_source, self.stage_seconds = 2.0, "camera-height", {"mapping": 30.0}
        self.dropped_blurry, self.check = 0, ""


def test_process_is_reused_with_its_saved_seconds_until_the_sfm_code_changes(tmp_path, monkeypatch):
    photos = tmp_path / "photos"
    photos.mkdir()
    for i in range(3):
        (photos / f"{i}.jpg").write_bytes(b"jpg" + bytes([i]))
    data = tmp_path / "data"
    calls = []

    def fake_process(opts, out):
        calls.append(out)
        out.mkdir(exist_ok=True)
        (out / "transforms.json").write_text("{}")
        return _Report(out)

    monkeypatch.setattr(rp, "process_photos", fake_process)
    code = {"hash": "one"}
    monkeypatch.setattr(code_version, "source_hash", lambda parts, root=None: code["hash"])
    opts = rp.RealPhotosOptions(images=photos)
    stages, reused = {}, []
    rp.process_or_reuse(opts, data, stages, reused, False, lambda s: None)
    assert len(calls) == 1 and reused == []
    record = json.loads((data / rp.PROCESS_RECORD).read_text())
    record["seconds"] = 41.5  # as if the SfM had taken 41.5 s
    (data / rp.PROCESS_RECORD).write_text(json.dumps(record))

    stages, reused = {}, []
    report = rp.process_or_reuse(opts, data, stages, reused, False, lambda s: None)
    assert len(calls) == 1 and stages["process"] == 41.5 and reused == ["process"]
    assert report.registered == 4 and report.stage_seconds == {"mapping": 30.0} and report.out == data

    code["hash"] = "two"  # the SfM code changed: made again
    stages, reused = {}, []
    rp.process_or_reuse(opts, data, stages, reused, False, lambda s: None)
    assert len(calls) == 2 and stages["process"] < 41.5 and reused == []
    rp.process_or_reuse(opts, data, {}, [], True, lambda s: None)  # --rerun: made again
    assert len(calls) == 3


def test_masks_are_reused_only_from_the_same_reference_mask_code_and_kind_of_capture(tmp_path, monkeypatch):
    import nerf2gs_plugin.masking.make_masks as mm

    data = tmp_path / "data"
    made = []

    def fake_make_masks(cfg, log=print):
        made.append(cfg.reference)
        (data / "masks").mkdir(parents=True, exist_ok=True)
        doc = {"reference": str(cfg.reference), "coverage": {"sky": 0.1}}
        (data / "masks" / "masks.json").write_text(json.dumps(doc))
        return doc

    monkeypatch.setattr(mm, "make_masks", fake_make_masks)
    code = {"hash": "one"}
    monkeypatch.setattr(code_version, "source_hash", lambda parts, root=None: code["hash"])
    opts = rp.RealPhotosOptions(images=tmp_path)
    ref = tmp_path / "ref-a"
    data.mkdir()
    (data / "transforms.json").write_text(json.dumps({"process": {"matching": "exhaustive"}, "frames": []}))
    rp.masks_or_reuse(opts, data, ref, {}, [], False, lambda s: None)
    stages, reused = {}, []
    assert rp.masks_or_reuse(opts, data, ref, stages, reused, False, lambda s: None)["coverage"] == {"sky": 0.1}
    assert len(made) == 1 and reused == ["masks"] and "masks" in stages
    rp.masks_or_reuse(opts, data, tmp_path / "ref-b", {}, [], False, lambda s: None)  # another reference
    code["hash"] = "two"
    rp.masks_or_reuse(opts, data, tmp_path / "ref-b", {}, [], False, lambda s: None)  # other mask code
    assert len(made) == 3
    (data / "transforms.json").write_text(json.dumps({"process": {"matching": "sequential"}, "frames": []}))
    rp.masks_or_reuse(opts, data, tmp_path / "ref-b", {}, [], False, lambda s: None)  # now a sequence: the motion route too
    assert len(made) == 4


def test_run_seconds_are_the_runs_own():
    assert rp.run_seconds({"trained": {"seconds": 50.0}, "measured": {"seconds": 4.5}}) == pytest.approx(54.5)
    assert rp.run_seconds({"trained": {"date": "2020"}, "measured": {"seconds": 4.5}}) is None  # saved before seconds were
    assert rp.run_seconds(None) is None
