"""PSNR of depth images (dcslam.eval.denoising)."""
import math

import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.eval.denoising import depth_psnr_db


class TestDepthPsnr:
    def test_known_value(self):
        clean = torch.tensor([[1.0, 2.0], [0.0, 4.0]])[None, None]
        pred = torch.tensor([[1.1, 2.0], [5.0, 3.8]])[None, None]  # the pixel without clean depth is ignored
        mse = (0.1 ** 2 + 0 + 0.2 ** 2) / 3
        assert float(depth_psnr_db(pred, clean)[0]) == pytest.approx(10 * math.log10(4.0 ** 2 / mse), abs=1e-4)
        assert float(depth_psnr_db(pred, clean)[0]) == pytest.approx(29.8227, abs=1e-4)

    def test_per_image_perfect_and_empty(self):
        clean = torch.stack([torch.full((1, 3, 3), 2.0), torch.zeros(1, 3, 3)])
        psnr = depth_psnr_db(clean.clone(), clean)
        assert math.isinf(float(psnr[0])) and math.isnan(float(psnr[1]))
        with pytest.raises(DcslamError):
            depth_psnr_db(clean, clean[:1])
