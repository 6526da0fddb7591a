"""``import dcslam`` puts MKL in its conditional-numerical-reproducibility mode: the ICP's normal equations (J^T J,
J^T r) come out with the same bits whichever kernels MKL would pick for the CPU."""
import importlib
import os
import subprocess
import sys

import dcslam

SCRIPT = """
import dcslam, hashlib, torch
torch.manual_seed(0)
J, r = torch.randn(20000, 6, dtype=torch.float64), torch.randn(20000, dtype=torch.float64)
print(hashlib.sha1((J.T @ J).numpy().tobytes() + (J.T @ r).numpy().tobytes()).hexdigest())
"""


def _normal_equations_hash(instructions: str) -> str:
    env = {k: v for k, v in os.environ.items() if k != "MKL_CBWR"}
    env["MKL_ENABLE_INSTRUCTIONS"] = instructions       # as a CPU without the wider instructions would run
    done = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True)
    return done.stdout.strip()


def test_the_normal_equations_have_the_same_bits_on_every_instruction_set():
    """Without the mode, this machine's MKL (AVX-512) gives three different J^T J for these three settings."""
    assert len({_normal_equations_hash(isa) for isa in ("AVX512", "AVX2", "SSE4_2")}) == 1


def test_a_mode_the_caller_chose_is_kept(monkeypatch):
    monkeypatch.setenv("MKL_CBWR", "AUTO")
    importlib.reload(dcslam)
    assert os.environ["MKL_CBWR"] == "AUTO"
    monkeypatch.delenv("MKL_CBWR")
    importlib.reload(dcslam)
    assert os.environ["MKL_CBWR"] == "COMPATIBLE"
