"""The trainings' optimizer: torch's AdamW, without the import of ``torch._dynamo`` that its first use costs.

torch wraps five methods of its optimizers for ``torch.compile``: ``step`` (autograd switched to the optimizer's
``differentiable`` setting between two dynamo graph breaks) and ``add_param_group`` (which the constructor calls),
``zero_grad``, ``state_dict`` and ``load_state_dict`` (kept out of compiled graphs). Each wrapper imports
``torch._dynamo`` on its first call (1.6-2.2 CPU-s, docs/training.md), paid once by every process that trains (a
Slurm job, a reproduce worker), for a compiler dcslam never calls. :data:`AdamW` is torch's AdamW calling the
methods those wrappers wrap (their ``__wrapped__``) and keeping ``step``'s autograd switch: the same arithmetic, bit
for bit (``tests/depth/test_optimizer.py``); where a torch version wraps them otherwise it is torch's own class.
:func:`adamw` builds one, or torch's own AdamW where ``torch._dynamo`` is loaded already (something compiles in this
process).
"""
from __future__ import annotations

import sys

import torch

# the methods of torch.optim.Optimizer that torch._disable_dynamo wraps
_DISABLED = ("add_param_group", "zero_grad", "state_dict", "load_state_dict")


def _plain_methods() -> dict | None:
    """``{name: function}``: AdamW's methods without their dynamo wrappers; None where one cannot be found."""
    methods = {}
    for name in _DISABLED:
        wrapped = getattr(getattr(torch.optim.Optimizer, name), "__wrapped__", None)
        if wrapped is None:
            return None
        methods[name] = wrapped
    step = torch.optim.AdamW.step  # _use_grad's wrapper (inside profile_hook_step's once an AdamW was made)
    while step is not None and getattr(step, "__code__", None) is not None and step.__code__.co_name != "_use_grad":
        step = getattr(step, "__wrapped__", None)
    plain_step = getattr(step, "__wrapped__", None)
    if plain_step is None:
        return None

    def step_without_dynamo(self, closure=None):
        previous = torch.is_grad_enabled()
        try:
            torch.set_grad_enabled(self.defaults["differentiable"])
            return plain_step(self, closure)
        finally:
            torch.set_grad_enabled(previous)

    methods["step"] = step_without_dynamo
    return methods


_PLAIN = _plain_methods()
#: torch's AdamW with the plain methods (torch's own class where they cannot be found)
AdamW = torch.optim.AdamW if _PLAIN is None else type("AdamW", (torch.optim.AdamW,), dict(_PLAIN))


def adamw(parameters, lr: float, weight_decay: float) -> torch.optim.AdamW:
    """``torch.optim.AdamW(parameters, lr=lr, weight_decay=weight_decay)``, built and stepped without importing
    ``torch._dynamo`` (the module docstring)."""
    cls = torch.optim.AdamW if "torch._dynamo" in sys.modules else AdamW
    return cls(parameters, lr=lr, weight_decay=weight_decay)
