"""One torch thread in these tests: the work is tiny, and OpenMP threads spinning on a shared
2-core machine make it tens of times slower."""

import pytest
import torch


@pytest.fixture(autouse=True)
def _one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
