"""Split and scale options reach the parsers from the DataManager's dataparser config (the train CLI)."""

import pytest

from nerf2gs_plugin.data import DataParserConfig
from nerf2gs_plugin.datamanagers.full_image import FullImageDataManagerConfig
from nerf2gs_plugin.errors import DataError


def _config(**options) -> FullImageDataManagerConfig:
    return FullImageDataManagerConfig(dataparser=DataParserConfig(**options))


def test_camera_height_metres_per_unit_holdout(street_copy, make_config):
    import json

    meta = json.loads((street_copy / "transforms.json").read_text())
    meta.pop("eval_splits")  # a capture without split keys
    meta["metres_per_unit"] = 7.0  # a wrong scale in the file: the options must override it
    meta.pop("up")
    (street_copy / "transforms.json").write_text(json.dumps(meta))
    dm = _config(camera_height=3.0).setup(data=street_copy, device="cpu")
    assert abs(dm.train_data.metres_per_unit - 1.0) < 0.05  # cameras 3 m above the road of a metric scene
    assert float(dm.train_data.up @ dm.train_data.up.new_tensor([0, 0, 1.0])) > 0.999
    assert dm.eval_split_names() == ["test"]
    dm = _config(metres_per_unit=2.0, holdout_every=0).setup(data=street_copy, device="cpu")
    assert dm.train_data.metres_per_unit == 2.0 and dm.eval_split_names() == []
    (street_copy / "sparse_pc.ply").unlink()
    meta.pop("ply_file_path")
    (street_copy / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(DataError, match="--metres-per-unit"):
        _config(camera_height=3.0).setup(data=street_copy, device="cpu")
