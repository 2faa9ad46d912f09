import pytest
import torch


@pytest.fixture(autouse=True, scope="session")
def one_torch_thread():
    """The machine is shared: extra intra-op threads only add synchronisation cost here."""
    torch.set_num_threads(1)
