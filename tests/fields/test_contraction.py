"""Scene contraction: values and finite gradients (positions require grad under a camera optimizer)."""

import torch

from nerf2gs_plugin.fields.contraction import contract, contraction_scale


def test_contraction_scale_values_and_finite_gradient_everywhere():
    x = torch.tensor([[0.0, 0.0, 0.0], [0.5, 0.1, -0.2], [0.3, -0.5, 0.1], [1.0, 0.0, 0.0], [2.0, 0.5, 0.0], [-4.0, 1.0, 3.0]],
                     requires_grad=True)
    s = contraction_scale(x)
    n = torch.tensor([2.0, 4.0])
    expected = (1.0 / n**2 * ((2.0 - 1.0 / n) / n) ** 2) ** (1.0 / 3.0)
    torch.testing.assert_close(s[:4], torch.ones(4))
    torch.testing.assert_close(s[4:], expected)
    (s.sum() + contract(x).sum()).backward()
    assert bool(torch.isfinite(x.grad).all())  # |x| = 0.5 (rows 1, 2) once gave NaN through the unused branch


def test_render_grid_coords_match_the_training_ops():
    """A render's one-pass coordinates and radii equal those of training's separate ops to float rounding,
    inside the box, on its faces and far outside."""
    from nerf2gs_plugin.fields.contraction import render_grid_coords, to_box_frame, to_grid_unit
    from nerf2gs_plugin.fields.street_field import _GridPositions

    torch.manual_seed(0)
    box = torch.tensor([[-1.0, -0.5, -2.0], [1.0, 0.5, 1.0]])
    x = torch.cat([torch.randn(4000, 3) * 4.0, torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.5, -2.0], [-0.5, 0.0, -0.5], [0.0, 0.0, -0.5]])])
    xb = to_box_frame(x, box)
    xg, scale = render_grid_coords(x, box)
    torch.testing.assert_close(xg, to_grid_unit(contract(xb)), rtol=0, atol=1e-6)
    torch.testing.assert_close(scale, contraction_scale(xb), rtol=1e-6, atol=0)
    grid, radius = _GridPositions(box), torch.rand(len(x)) * 0.01
    with torch.enable_grad():
        xg_train, r_train = grid.grid_coords(x, radius)
    with torch.no_grad():
        xg_render, r_render = grid.grid_coords(x, radius)
    torch.testing.assert_close(xg_render, xg_train, rtol=0, atol=1e-6)
    torch.testing.assert_close(r_render, r_train, rtol=1e-6, atol=0)
