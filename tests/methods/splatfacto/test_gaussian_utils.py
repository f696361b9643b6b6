"""Shared Gaussian helpers: SH, quaternions, kNN scales and the 3DGS PLY round trip."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nerf2gs_plugin.errors import DataError
from nerf2gs_plugin.methods.gaussian_utils import knn_mean_distance, read_gaussian_ply, write_gaussian_ply
from nerf2gs_plugin.utils.quaternions import quat_to_rotmat, random_quats, rotmat_to_quat
from nerf2gs_plugin.utils.sh import rgb_to_sh, sh_basis, sh_to_rgb


def test_sh_rgb_round_trip_and_basis():
    rgb = torch.rand(10, 3)
    assert torch.allclose(sh_to_rgb(rgb_to_sh(rgb)), rgb, atol=1e-6)
    d = torch.nn.functional.normalize(torch.randn(2000, 3), dim=-1)
    B = sh_basis(3, d)
    assert B.shape == (2000, 16)
    # real SH are orthonormal on the sphere: Monte Carlo Gram matrix ~ I / (4 pi)
    gram = B.T @ B / 2000 * 4 * np.pi
    assert torch.allclose(gram, torch.eye(16), atol=0.25)


def test_quaternion_conversions():
    q = random_quats(100, torch.Generator().manual_seed(1))
    R = quat_to_rotmat(q)
    assert torch.allclose(R @ R.transpose(1, 2), torch.eye(3).expand(100, 3, 3), atol=1e-5)
    assert torch.allclose(torch.det(R), torch.ones(100), atol=1e-5)
    q2 = rotmat_to_quat(R)
    assert torch.allclose(quat_to_rotmat(q2), R, atol=1e-5)


def test_knn_mean_distance_on_grid():
    g = torch.stack(torch.meshgrid(*(torch.arange(5.0),) * 3, indexing="ij"), -1).reshape(-1, 3) * 0.1
    d = knn_mean_distance(g, k=3, chunk=7)
    assert torch.allclose(d, torch.full_like(d, 0.1), atol=1e-5)


def test_ply_round_trip(tmp_path):
    n = 37
    vals = dict(means=torch.randn(n, 3), log_scales=torch.randn(n, 3), quats=torch.randn(n, 4),
                opacity_logits=torch.randn(n), features_dc=torch.randn(n, 3), features_rest=torch.randn(n, 15, 3))
    path = tmp_path / "g.ply"
    write_gaussian_ply(path, **vals)
    header = path.read_bytes().split(b"end_header")[0].decode()
    for name in ("property float x", "f_dc_2", "f_rest_44", "property float opacity", "scale_2", "rot_3"):
        assert name in header
    back = read_gaussian_ply(path)
    for k, v in vals.items():
        assert torch.equal(back[k], v), k
    # f_rest is channel-major as in 3DGS: f_rest_0..14 are the red coefficients
    raw = np.frombuffer(path.read_bytes().split(b"end_header\n", 1)[1], dtype="<f4").reshape(n, -1)
    assert np.allclose(raw[:, 9 : 9 + 15], vals["features_rest"][:, :, 0].numpy())


def test_ply_errors(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"not a ply")
    with pytest.raises(DataError):
        read_gaussian_ply(bad)
    with pytest.raises(DataError):
        read_gaussian_ply(tmp_path / "missing.ply")
    # one parser for every PLY (data/ply.py): a cut-off 3DGS file says so, naming the file
    good = tmp_path / "g.ply"
    write_gaussian_ply(good, means=torch.zeros(4, 3), log_scales=torch.zeros(4, 3), quats=torch.zeros(4, 4),
                       opacity_logits=torch.zeros(4), features_dc=torch.zeros(4, 3), features_rest=torch.zeros(4, 0, 3))
    good.write_bytes(good.read_bytes()[:-8])
    with pytest.raises(DataError, match=r"g.ply: PLY file is truncated \(4 vertices declared, 3 present\)"):
        read_gaussian_ply(good)
