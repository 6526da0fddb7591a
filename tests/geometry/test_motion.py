import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.motion import relative_motion
from dcslam.geometry.se3 import from_rotation_translation, se3_exp, so3_exp

ANGLES = (0.0, 1e-8, 1e-3, math.pi / 2, math.pi - 1e-6, math.pi)
AXIS = torch.tensor([2.0, -3.0, 6.0], dtype=torch.float64) / 7.0        # a unit axis off every coordinate axis
DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _pose(angle: float, t=(0.3, -1.2, 4.0), axis: torch.Tensor = AXIS) -> torch.Tensor:
    return from_rotation_translation(so3_exp(axis * angle), torch.tensor(t, dtype=torch.float64))


def _random_poses(n: int, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return se3_exp(torch.randn(n, 6, generator=g, dtype=torch.float64))


class TestRelativeMotion:
    @pytest.mark.parametrize("angle", ANGLES)
    def test_known_angles(self, angle):
        T_a = _random_poses(1, seed=3)[0]
        T_b = T_a @ _pose(angle)
        metres, radians = relative_motion(T_a, T_b)
        assert float(metres) == pytest.approx(math.hypot(0.3, 1.2, 4.0), rel=1e-12)
        assert abs(float(radians) - angle) <= 1e-14 + 1e-12 * angle           # acos: ~1e-8 near 0, 1e-10 near pi

    @pytest.mark.parametrize("angle", ANGLES)
    def test_numpy_as_torch(self, angle):
        T_a, T_b = np.eye(4), _pose(angle).numpy()
        metres, radians = relative_motion(T_a, T_b)
        assert not isinstance(radians, torch.Tensor) and np.asarray(radians).dtype == np.float64
        assert abs(float(radians) - angle) <= 1e-14 + 1e-12 * angle
        assert float(metres) == pytest.approx(float(relative_motion(torch.eye(4), _pose(angle))[0]), rel=1e-15)

    def test_acos_of_the_trace_loses_small_angles(self):
        """The angle acos of the trace reads as 0 below ~1e-8 rad; relative_motion keeps it."""
        R = so3_exp(AXIS * 1e-9)
        assert math.acos(min(1.0, (float(torch.trace(R)) - 1) / 2)) == 0.0
        assert float(relative_motion(torch.eye(4, dtype=torch.float64),
                                     from_rotation_translation(R, torch.zeros(3, dtype=torch.float64)))[1]) \
            == pytest.approx(1e-9, rel=1e-9)

    def test_not_quite_orthonormal_poses_against_themselves(self):
        """Rotations printed to 7 digits (as KITTI's pose files are) are orthonormal to ~1e-7: a true inverse still
        finds no motion between a pose and itself, where the transpose would find ~1e-7 rad."""
        T = np.round(_random_poses(20, seed=1).numpy(), 7)
        R = T[:, :3, :3]
        assert np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max() > 1e-8
        metres, radians = relative_motion(T, T)
        assert metres.shape == radians.shape == (20,)
        assert metres.max() < 1e-12 and radians.max() < 1e-12

    @pytest.mark.parametrize("device", DEVICES)
    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    def test_dtypes_and_devices(self, dtype, device):
        T_a = _random_poses(4, seed=2).to(dtype=dtype, device=device)
        T_b = (T_a.double() @ _pose(0.25).to(device)).to(dtype)
        metres, radians = relative_motion(T_a, T_b)
        assert metres.dtype == radians.dtype == torch.float64 and radians.device.type == device
        assert metres.shape == radians.shape == (4,)
        tol = 1e-12 if dtype == torch.float64 else 1e-5
        torch.testing.assert_close(radians.cpu(), torch.full((4,), 0.25, dtype=torch.float64), atol=tol, rtol=0)
        # a float32 pose keeps a small angle that acos of its trace would round to 0
        small = _pose(1e-6, t=(0, 0, 0)).to(dtype=dtype, device=device)
        assert float(relative_motion(torch.eye(4, dtype=dtype, device=device), small)[1]) \
            == pytest.approx(1e-6, rel=1e-6 if dtype == torch.float64 else 1e-2)

    def test_broadcasts(self):
        T = _random_poses(5)
        metres, radians = relative_motion(T[0], T)
        assert metres.shape == (5,) and float(metres[0]) < 1e-12 and float(radians[0]) < 1e-12
        for i in range(5):
            m, r = relative_motion(T[0], T[i])
            assert float(m) == pytest.approx(float(metres[i]), rel=1e-14, abs=1e-14)
            assert float(r) == pytest.approx(float(radians[i]), rel=1e-14, abs=1e-14)

    def test_shape_errors(self):
        with pytest.raises(DcslamError, match=r"\(\.\.\., 4, 4\)"):
            relative_motion(torch.eye(3), torch.eye(4))
        with pytest.raises(DcslamError, match=r"\(\.\.\., 4, 4\)"):
            relative_motion(np.eye(4), np.zeros(4))
        with pytest.raises(DcslamError, match="broadcast"):
            relative_motion(_random_poses(2), _random_poses(3))

    def test_gradcheck(self):
        T_a = _random_poses(3, seed=4).requires_grad_()
        T_b = (T_a.detach() @ se3_exp(0.4 * torch.randn(3, 6, dtype=torch.float64))).requires_grad_()
        assert torch.autograd.gradcheck(lambda a, b: relative_motion(a, b), (T_a, T_b))


def test_torch_motion_does_not_import_sympy():
    """torch.broadcast_shapes imports sympy on its first call (about half a CPU-second per process): the torch path
    broadcasts the batch shapes without it. Checked in a fresh process, where nothing else has imported it."""
    code = ("import sys, torch\n"
            "from dcslam.geometry.motion import relative_motion\n"
            "assert 'sympy' not in sys.modules, 'torch itself imported sympy'\n"
            "m, r = relative_motion(torch.eye(4).expand(2, 4, 4), torch.eye(4, dtype=torch.float64))\n"
            "assert m.shape == (2,) and r.shape == (2,)\n"
            "print('sympy' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert out.stdout.strip() == "False"
