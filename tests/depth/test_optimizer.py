"""dcslam.depth.optimizer: torch's AdamW arithmetic, bit for bit, without importing torch._dynamo."""
import os
import subprocess
import sys

import pytest
import torch

from dcslam.depth.optimizer import AdamW


def _train(make, steps: int = 6):
    """A small network trained by the optimizer ``make(parameters)`` builds: its parameters and the optimizer's state
    after ``steps`` steps, with a state_dict round trip half way (what resuming from last.pt does)."""
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Conv2d(2, 4, 3, padding=1), torch.nn.ReLU(),
                                torch.nn.Conv2d(4, 1, 3, padding=1))
    optimizer = make(model.parameters())
    x = torch.randn(2, 2, 12, 20)
    for step in range(steps):
        model(x).square().mean().backward()
        optimizer.step()
        optimizer.zero_grad()
        if step == steps // 2:
            state = optimizer.state_dict()
            optimizer = make(model.parameters())
            optimizer.load_state_dict(state)
    return [p.detach().clone() for p in model.parameters()], optimizer.state_dict()


@pytest.mark.parametrize("lr, weight_decay", [(1e-3, 0.01), (5e-2, 0.0)])
def test_the_same_bits_as_torchs_adamw(lr, weight_decay):
    assert AdamW is not torch.optim.AdamW  # this torch's wrappers were found
    ours, our_state = _train(lambda p: AdamW(p, lr=lr, weight_decay=weight_decay))
    theirs, their_state = _train(lambda p: torch.optim.AdamW(p, lr=lr, weight_decay=weight_decay))
    assert all(torch.equal(a, b) for a, b in zip(ours, theirs))
    assert our_state["param_groups"] == their_state["param_groups"]
    for key, state in their_state["state"].items():
        assert all(torch.equal(our_state["state"][key][name], value) for name, value in state.items())


def test_the_step_runs_without_autograd_and_restores_it():
    """Under autograd, torch refuses the in-place update of a leaf that requires its gradient: the step turns it off
    and gives the caller's mode back either way."""
    weight = torch.nn.Parameter(torch.ones(3))
    optimizer = AdamW([weight], lr=0.1, weight_decay=0.0)
    weight.sum().backward()
    with torch.enable_grad():
        optimizer.step()
        assert torch.is_grad_enabled()
    with torch.no_grad():
        optimizer.step()
        assert not torch.is_grad_enabled()
    assert torch.allclose(weight.detach(), torch.full((3,), 0.8))  # two steps of lr 0.1 down the gradient's sign


def test_no_import_of_torch_dynamo_then_torchs_own_class_once_it_is_loaded():
    """A fresh process (where nothing else has imported torch._dynamo): a whole training cycle leaves it unloaded;
    once something has loaded it, adamw hands out torch's own AdamW."""
    code = ("import sys, torch\n"
            "from dcslam.depth.optimizer import AdamW, adamw\n"
            "w = torch.nn.Parameter(torch.ones(3))\n"
            "opt = adamw([w], 0.1, 0.01)\n"
            "w.square().sum().backward(); opt.step(); opt.zero_grad(); opt.load_state_dict(opt.state_dict())\n"
            "print('torch._dynamo' in sys.modules, type(opt) is torch.optim.AdamW)\n"
            "import torch._dynamo\n"
            "print(type(adamw([w], 0.1, 0.01)) is torch.optim.AdamW)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False", "True"]
