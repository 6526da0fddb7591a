import pytest
import torch

from dcslam.depth.models.dncnn import DnCNN
from dcslam.errors import DcslamError


def test_architecture_17_layers_64_channels():
    net = DnCNN()
    convs = [m for m in net.modules() if isinstance(m, torch.nn.Conv2d)]
    assert len(convs) == 17
    assert all(c.out_channels == 64 for c in convs[:-1]) and convs[-1].out_channels == 1


def test_residual_learning():
    net = DnCNN(depth=3, features=4)
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
    x = torch.rand(2, 1, 8, 8)
    assert torch.equal(net(x), x)  # zero residual → identity


def test_bad_shape():
    with pytest.raises(DcslamError):
        DnCNN()(torch.rand(1, 2, 8, 8))
    with pytest.raises(DcslamError):
        DnCNN(depth=2)
