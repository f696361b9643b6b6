import torch

from nerf2gs_plugin.utils.voxels import unique_cells


def test_unique_cells_matches_torch_rowwise_unique():
    g = torch.Generator().manual_seed(0)
    for cells in (torch.randint(-7, 9, (5000, 3), generator=g), torch.randint(0, 3, (200, 2), generator=g),
                  torch.tensor([[5, -1, 2]]), torch.randint(-2**20, 2**20, (3000, 3), generator=g)):
        rows, inverse = unique_cells(cells)
        want_rows, want_inverse = torch.unique(cells, dim=0, return_inverse=True)
        assert torch.equal(rows, want_rows)
        assert torch.equal(inverse, want_inverse)
        assert torch.equal(rows[inverse], cells)


def test_unique_cells_falls_back_when_the_key_would_overflow():
    cells = torch.tensor([[0, 0, 0], [2**40, 2**40, 2**40], [0, 0, 0]])
    rows, inverse = unique_cells(cells)
    assert rows.tolist() == [[0, 0, 0], [2**40, 2**40, 2**40]]
    assert inverse.tolist() == [0, 1, 0]
