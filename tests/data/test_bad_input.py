"""Bad input: each case is a DataError whose one-line message names the file, and through
``ns2gs-data`` an exit status 2 with one ``error: ...`` line on stderr (no traceback)."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from nerf2gs_plugin.cli import data as data_cli
from nerf2gs_plugin.data import parse_dataset
from nerf2gs_plugin.data.images import load_image, load_mask
from nerf2gs_plugin.errors import DataError


def _edit(root: Path, fn) -> None:
    meta = json.loads((root / "transforms.json").read_text())
    fn(meta)
    (root / "transforms.json").write_text(json.dumps(meta))


def missing_image(root: Path) -> str:
    (root / "images" / "train_0002.png").unlink()
    return "train_0002.png"


def unreadable_image(root: Path) -> str:
    (root / "images" / "train_0000.png").write_bytes(b"not a png at all")
    return "train_0000.png"


def malformed_json(root: Path) -> str:
    (root / "transforms.json").write_text('{"frames": [ {"file_path": "images/a.png",, }')
    return "transforms.json"


def wrong_mask_size(root: Path) -> str:
    cv2.imwrite(str(root / "masks" / "ground" / "train_0000.png"), np.zeros((10, 10), np.uint8))
    return "train_0000.png"


def empty_split(root: Path) -> str:
    _edit(root, lambda m: m["eval_splits"].update(street=[]))
    return "transforms.json"


def non_rigid_transform(root: Path) -> str:
    def scale(meta):
        t = np.array(meta["frames"][1]["transform_matrix"])
        t[:3, 0] *= 2.0
        meta["frames"][1]["transform_matrix"] = t.tolist()

    _edit(root, scale)
    return "transforms.json"


CASES = [unreadable_image, malformed_json, wrong_mask_size, empty_split, non_rigid_transform]
MESSAGES = {
    "missing_image": "does not exist",
    "unreadable_image": "cannot read image",
    "malformed_json": "malformed JSON",
    "wrong_mask_size": "mask is 10x10 but its image is 48x32",
    "empty_split": "split 'street' is empty",
    "non_rigid_transform": "not rigid",
}


def _trigger(root: Path) -> None:
    """What a training run does with a dataset: parse every split and read its files."""
    from nerf2gs_plugin.data import list_splits

    for split in list_splits(root):
        out = parse_dataset(root, split)
        for i, p in enumerate(out.image_filenames):
            hw = load_image(p).shape[:2]
            for masks in out.mask_filenames.values():
                if masks[i] is not None:
                    load_mask(masks[i], hw)


@pytest.mark.parametrize("case", CASES, ids=lambda f: f.__name__)
def test_bad_input_is_one_line_naming_the_file(street_copy, case):
    name = case(street_copy)
    with pytest.raises(DataError) as e:
        _trigger(street_copy)
    msg = str(e.value)
    assert "\n" not in msg
    assert name in msg and MESSAGES[case.__name__] in msg


def test_missing_images_are_skipped_with_one_warning(street_copy):
    """instant-ngp's samples list frames whose image is absent: skipped, one warning counting them."""
    import warnings

    missing_image(street_copy)
    (street_copy / "images" / "train_0004.png").unlink()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from nerf2gs_plugin.data import list_splits

        splits = list_splits(street_copy)
        train = parse_dataset(street_copy, "train")
    msgs = [str(w.message) for w in caught if "does not exist" in str(w.message)]
    assert len(set(msgs)) == 1 and "2 of" in msgs[0] and "skipped" in msgs[0]
    names = [p.name for p in train.image_filenames]
    assert "train_0002.png" not in names and "train_0004.png" not in names and len(names) == 4
    assert "street" in splits


def _run_cli(monkeypatch, capsys, *args: str) -> tuple[int, str]:
    monkeypatch.setattr(sys, "argv", ["ns2gs-data", *args])
    with pytest.raises(SystemExit) as e:
        data_cli.entrypoint()
    return int(e.value.code), capsys.readouterr().err


@pytest.mark.parametrize("case", [malformed_json, wrong_mask_size, non_rigid_transform], ids=lambda f: f.__name__)
def test_cli_exit_code_2_and_one_error_line(street_copy, case, monkeypatch, capsys, tmp_path):
    name = case(street_copy)
    code, err = _run_cli(monkeypatch, capsys, "preview", str(street_copy), "--out", str(tmp_path / "p.png"), "--rows", "6")
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and name in lines[0]
    assert "Traceback" not in err


def test_colmap_folder_without_images(small_street, write_colmap, tmp_path, monkeypatch, capsys):
    root = write_colmap(small_street, tmp_path / "colmap")
    shutil.rmtree(root / "images")
    with pytest.raises(DataError, match="no 'images/' folder") as e:
        parse_dataset(root, "train")
    assert str(root) in str(e.value)
    code, err = _run_cli(monkeypatch, capsys, "preview", str(root))
    assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1
    # one image of the model missing from images/
    root2 = write_colmap(small_street, tmp_path / "colmap2")
    (root2 / "images" / "train_0003.png").unlink()
    with pytest.raises(DataError, match="train_0003.png"):
        parse_dataset(root2, "train")


def test_not_a_dataset_and_bad_flags(tmp_path, monkeypatch, capsys):
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match="not a dataset"):
        parse_dataset(tmp_path / "empty")
    code, err = _run_cli(monkeypatch, capsys, "synth-street", str(tmp_path / "s"), "--num-train", "1")
    assert code == 2 and err.startswith("error: ") and "num_train" in err


def test_duplicate_file_path_frames_warn_once(street_copy, capsys):
    """Two frames with the same file_path warn once instead of training silently."""
    _edit(street_copy, lambda m: m["frames"].append(dict(m["frames"][1])))
    parse_dataset(street_copy, "train")
    parse_dataset(street_copy, "train")
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "transforms.json: 1 frame(s) repeat the file_path" in err[0]
