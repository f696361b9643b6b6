"""A processed capture against surveyed cameras (Strecha's ``.camera`` files): ATE and the metric
scale's error, on cameras made from a known similarity."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nerf2gs_bench.capture_truth import read_strecha_camera, truth_report, vertical_axis
from nerf2gs_plugin.errors import DataError


def _rot(axis: int, deg: float) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _write_camera(path, R_cv, centre):
    rows = ["2759.48 0 1520.69", "0 2764.16 1006.81", "0 0 1", "0 0 0"]
    rows += [" ".join(f"{v:.9f}" for v in r) for r in R_cv] + [" ".join(f"{v:.9f}" for v in centre), "3072 2048"]
    path.write_text("\n".join(rows) + "\n")


def _capture(tmp_path, metres_per_unit: float):
    """Six true cameras on an arc (metres, OpenCV axes), and a dataset whose cameras are the truth
    shrunk 4x, turned and moved (the SfM frame): 0.25 units per metre, so 4 metres per unit is right."""
    truth = tmp_path / "truth"
    truth.mkdir(parents=True)
    S = _rot(2, 30.0) @ _rot(0, 10.0)
    frames = []
    for i in range(6):
        R_cv = _rot(1, 12.0 * i) @ _rot(0, 3.0 * (i % 2))
        centre = np.array([3.0 * np.sin(0.2 * i), 0.1 * i, 8.0 - 3.0 * np.cos(0.2 * i)])
        _write_camera(truth / f"{i:04d}.jpg.camera", R_cv, centre)
        c2w = read_strecha_camera(truth / f"{i:04d}.jpg.camera")
        est = np.eye(4)
        est[:3, :3] = S @ c2w[:, :3]
        est[:3, 3] = 0.25 * S @ c2w[:, 3] + np.array([1.0, -2.0, 0.5])
        frames.append({"file_path": f"images/{i:04d}.jpg", "transform_matrix": est.tolist()})
    data = tmp_path / "data"
    data.mkdir()
    (data / "transforms.json").write_text(json.dumps({"frames": frames[:5], "metres_per_unit": metres_per_unit,
                                                      "up": (S @ np.array([0.0, -1.0, 0.0])).tolist()}))
    return data, truth


def test_strecha_camera_is_read_in_opengl_axes(tmp_path):
    _write_camera(tmp_path / "a.camera", np.eye(3), np.array([1.0, 2.0, 3.0]))
    c2w = read_strecha_camera(tmp_path / "a.camera")
    assert np.allclose(c2w[:, :3], np.diag([1.0, -1.0, -1.0])) and np.allclose(c2w[:, 3], [1, 2, 3])
    (tmp_path / "b.camera").write_text("1 2 3\n")
    with pytest.raises(DataError, match="not a Strecha .camera file"):
        read_strecha_camera(tmp_path / "b.camera")


def test_exact_cameras_give_zero_ate_and_the_scale_error_of_the_metric_scale(tmp_path):
    data, truth = _capture(tmp_path, metres_per_unit=4.0)
    r = truth_report(data, truth)
    assert r["frames_compared"] == 5 and r["registered_fraction"] == pytest.approx(5 / 6)
    assert r["ate_m"] < 1e-6 and r["rotation_error_deg"] < 1e-4 and abs(r["scale_error_percent"]) < 1e-6
    data2, truth2 = _capture(tmp_path / "b", metres_per_unit=4.4)  # camera-height scale 10% too large
    assert truth_report(data2, truth2)["scale_error_percent"] == pytest.approx(10.0, abs=1e-6)


def test_too_few_matching_names_is_one_clear_error(tmp_path):
    data, truth = _capture(tmp_path, 4.0)
    for f in truth.glob("*.camera"):
        f.rename(f.with_name(f.name.replace(".jpg", ".png")))
    with pytest.raises(DataError, match="registered frames have a ground-truth camera"):
        truth_report(data, truth)


def test_true_up_is_the_surveyed_axis_nearest_the_cameras_mean_up():
    assert np.allclose(vertical_axis(np.array([-0.13, 0.12, -0.98])), [0, 0, -1])  # cameras pitched up at a facade
    assert np.allclose(vertical_axis(np.array([0.1, 0.9, 0.2])), [0, 1, 0])
