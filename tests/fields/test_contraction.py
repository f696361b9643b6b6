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
