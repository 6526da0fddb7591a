"""The analytic street scene: rendering through a mask casts the same rays as the full render."""
import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory


def test_masked_render_equals_full_render_on_the_mask():
    H, W = 60, 200
    scene, K, T = StreetScene(3, length=40.0), kitti_K(H, W), street_trajectory(3)[2]
    mask = lidar_mask(H, W, row_step=3, col_step=2)
    full = scene.render(T, K, H, W)
    masked = scene.render(T, K, H, W, mask=mask)
    assert masked.shape == (H, W)
    assert torch.equal(masked[mask], full[mask])
    assert not bool(masked[~mask].any())
    assert bool((masked[mask] > 0).any())


def test_masked_render_refuses_a_mask_of_another_size():
    with pytest.raises(DcslamError, match="mask has shape"):
        StreetScene(0).render(torch.eye(4, dtype=torch.float64), kitti_K(30, 40), 30, 40,
                              mask=torch.ones(30, 41, dtype=torch.bool))
