import torch

from nerf2gs_plugin.utils.resize import area_resize


def test_same_size_is_the_image_itself_and_a_halving_averages_each_2x2_block():
    img = torch.arange(4 * 6 * 3, dtype=torch.float32).reshape(4, 6, 3)
    assert area_resize(img, (4, 6)) is img
    half = area_resize(img, (2, 3))
    assert half.shape == (2, 3, 3)
    assert torch.allclose(half[0, 0], img[:2, :2].reshape(-1, 3).mean(0))
    assert area_resize(img.to(torch.float64), (2, 3)).dtype == torch.float32
