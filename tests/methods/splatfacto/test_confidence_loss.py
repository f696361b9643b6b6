"""The image loss with a per-pixel confidence (reference renders, ``--augment.confidence``)."""

import torch

from nerf2gs_plugin.methods.splatfacto.shared import image_loss


def _pair(h=24, w=40):
    g = torch.Generator().manual_seed(0)
    return torch.rand(h, w, 3, generator=g).requires_grad_(True), torch.rand(h, w, 3, generator=g)


def test_all_ones_is_the_plain_loss():
    pred, gt = _pair()
    plain = image_loss({"rgb": pred}, {"image": gt}, 0.2)["main_loss"]
    ones = image_loss({"rgb": pred}, {"image": gt, "confidence": torch.ones(24, 40, 1)}, 0.2)["main_loss"]
    assert torch.allclose(plain, ones, rtol=1e-6, atol=1e-7)


def test_pixels_the_reference_does_not_know_get_no_gradient():
    pred, gt = _pair()
    conf = torch.ones(24, 40, 1)
    conf[:, :20] = 0.0  # the left half: a surface no training view saw
    image_loss({"rgb": pred}, {"image": gt, "confidence": conf}, 0.2)["main_loss"].backward()
    g = pred.grad.abs().sum(-1)
    assert float(g[:, :15].max()) == 0.0  # beyond the SSIM window's reach of the confident half
    assert bool((g[:, 20:] > 0).all())
    # half the confidence, half the loss
    half = image_loss({"rgb": pred}, {"image": gt, "confidence": torch.full((24, 40, 1), 0.5)}, 0.2)["main_loss"]
    full = image_loss({"rgb": pred}, {"image": gt}, 0.2)["main_loss"]
    assert torch.allclose(half, 0.5 * full, rtol=1e-5)
