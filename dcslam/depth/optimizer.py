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


def _unwrap(method, wrapper: str, module: str):
    """The function that ``method`` wraps through the wrapper function named ``wrapper`` defined in torch's file
    ``module`` (outer ``functools.wraps`` wrappers walked through); None where there is no such wrapper."""
    while method is not None:
        code = getattr(method, "__code__", None)
        if code is not None and code.co_name == wrapper and code.co_filename.endswith(module):
            return getattr(method, "__wrapped__", None)
        method = getattr(method, "__wrapped__", None)
    return None


def _plain_methods() -> dict | None:
    """``{name: function}``: AdamW's methods without their dynamo wrappers; None where one cannot be found."""
    methods = {name: _unwrap(getattr(torch.optim.Optimizer, name), "inner", "_compile.py") for name in _DISABLED}
    # step: _use_grad's wrapper (inside profile_hook_step's once an AdamW was made)
    plain_step = _unwrap(torch.optim.AdamW.step, "_use_grad", "optimizer.py")
    if plain_step is None or None in methods.values():
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
