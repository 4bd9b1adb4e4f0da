"""One torch thread per test process: the trainers' updates here are tiny, and CI's two cores are
shared with SUMO and the vector envs' workers."""

import pytest


@pytest.fixture(autouse=True)
def _one_torch_thread():
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
