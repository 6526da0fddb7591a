"""SLAM tests work on small tensors, where torch's intra-op threads cost more than they give on a shared 2-core
machine (several times slower under load); run them on one thread and restore the setting afterwards."""
import pytest
import torch


@pytest.fixture(autouse=True)
def _one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
