import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from dcslam.errors import DcslamError
from dcslam.eval.surface import (SurfaceErrors, SurfaceSettings, depth_edges, depth_surface, mean_surface_errors,
                                 surface_errors)

K = np.array([[50.0, 0, 16], [0, 50.0, 12], [0, 0, 1]])
H, W = 24, 32


def plane_depth(normal, point, K=K, shape=(H, W)):
    """Depth of the plane through ``point`` with ``normal`` along each pixel's ray. Shape: (H, W) float64."""
    v, u = np.mgrid[:shape[0], :shape[1]].astype(np.float64)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    return np.dot(normal, point) / (rays @ normal)


N1 = Rotation.from_euler("xy", [30, -20], degrees=True).apply([0.0, 0.0, -1.0])   # faces the camera
P0 = np.array([0.3, -0.2, 10.0])


def image(depth, dtype):
    return torch.as_tensor(np.asarray(depth), dtype=dtype)


def holes(depth, fraction, seed):
    out = depth.copy()
    out[np.random.default_rng(seed).random(depth.shape) < fraction] = 0
    return out


def test_plane_against_itself(dtype):
    ref = plane_depth(N1, P0)
    e = surface_errors(image(ref, dtype), image(ref, dtype), K)
    assert e.normal_mean_deg == pytest.approx(0, abs=1e-9) and e.normal_median_deg == pytest.approx(0, abs=1e-9)
    assert e.p2p_mean_m == 0 and e.p2p_rmse_m == 0
    assert e.normal_pixels == e.p2p_pixels == H * W
    assert e.edge_pixels == 0 and math.isnan(e.flying_share)      # a smooth plane has no depth edge


@pytest.mark.parametrize("degrees", [3.0, 10.0, 25.0])
def test_plane_tilted_by_a_known_angle(dtype, degrees):
    axis = np.cross(N1, [1.0, 0.0, 0.0])
    axis /= np.linalg.norm(axis)
    N2 = Rotation.from_rotvec(np.radians(degrees) * axis).apply(N1)
    e = surface_errors(image(plane_depth(N2, P0), dtype), image(plane_depth(N1, P0), dtype), K)
    assert e.normal_mean_deg == pytest.approx(degrees, abs=0.1)
    assert e.normal_median_deg == pytest.approx(degrees, abs=0.1)
    assert e.p2p_mean_m > 0


def test_plane_offset_along_its_normal(dtype):
    delta = 0.25
    ref = plane_depth(N1, P0)
    further = plane_depth(N1, P0 - delta * N1)           # the normal faces the camera: -n points away from it
    e = surface_errors(image(further, dtype), image(ref, dtype), K)
    assert e.p2p_mean_m == pytest.approx(delta, abs=1e-5) and e.p2p_rmse_m == pytest.approx(delta, abs=1e-5)
    assert e.normal_mean_deg == pytest.approx(0, abs=0.01)


def test_holes_are_ignored(dtype):
    delta = 0.25
    ref = plane_depth(N1, P0)
    scored, reference = holes(plane_depth(N1, P0 - delta * N1), 0.1, 1), holes(ref, 0.05, 2)
    e = surface_errors(image(scored, dtype), image(reference, dtype), K)
    assert e.p2p_mean_m == pytest.approx(delta, abs=1e-5) and e.p2p_rmse_m == pytest.approx(delta, abs=1e-5)
    assert e.normal_mean_deg == pytest.approx(0, abs=0.01)
    both = int(((scored > 0) & (reference > 0)).sum())
    assert 0 < e.p2p_pixels <= both < H * W                  # only pixels with both a scored and a reference point
    assert surface_errors(image(np.zeros((H, W)), dtype), image(ref, dtype), K).p2p_pixels == 0
    assert surface_errors(image(ref, dtype), image(np.zeros((H, W)), dtype), K) is None


def step(columns=20, rows=8, at=10):
    """Fronto-parallel planes at 5 m (columns < at) and 10 m: (depth (rows, columns), K)."""
    depth = np.full((rows, columns), 10.0)
    depth[:, :at] = 5.0
    return depth, np.array([[40.0, 0, columns / 2], [0, 40.0, rows / 2], [0, 0, 1]])


def test_clean_step_has_no_flying_pixels(dtype):
    ref, K_step = step()
    e = surface_errors(image(ref, dtype), image(ref, dtype), K_step)
    # edge at columns 9 | 10; within 2 px: columns 7..12, every row
    assert e.edge_pixels == 6 * 8 and e.flying_pixels == 0 and e.flying_share == 0


def test_mixed_depths_across_a_step_are_flying(dtype):
    ref, K_step = step()
    mixed = ref.copy()
    mixed[:, 8:12] = [6.0, 7.0, 8.0, 9.0]       # linear mix of 5 m and 10 m: 1 to 2 m from either side
    e = surface_errors(image(mixed, dtype), image(ref, dtype), K_step)
    assert e.edge_pixels == 6 * 8 and e.flying_pixels == 4 * 8 and e.flying_share == pytest.approx(4 / 6)
    # an edge drawn one pixel off lies on the other side's surface: not flying
    shifted = ref.copy()
    shifted[:, 10] = 5.0
    assert surface_errors(image(shifted, dtype), image(ref, dtype), K_step).flying_pixels == 0


def test_mixed_step_with_holes(dtype):
    ref, K_step = step()
    mixed = ref.copy()
    mixed[:, 8:12] = [6.0, 7.0, 8.0, 9.0]
    mixed[0] = 0                                # no scored point on the top row
    ref_holes = ref.copy()
    ref_holes[7] = 0                            # no reference on the bottom row
    e = surface_errors(image(mixed, dtype), image(ref_holes, dtype), K_step)
    assert e.edge_pixels == 6 * 6 and e.flying_pixels == 4 * 6 and e.flying_share == pytest.approx(4 / 6)


def test_a_structure_too_thin_for_a_normal_is_a_surface_too(dtype):
    ref, K_step = step()
    ref[:, 15] = 5.0                            # a pole one pixel wide: no horizontal neighbour on its surface
    e = surface_errors(image(ref, dtype), image(ref, dtype), K_step)
    assert e.flying_pixels == 0 and e.edge_pixels == 12 * 8    # columns 7..18: near the step or the pole
    assert e.p2p_pixels == 20 * 8 - 8           # the pole has no normal: no plane to measure from
    mixed = ref.copy()
    mixed[:, 15] = 7.5                          # half way between the pole and the background
    assert surface_errors(image(mixed, dtype), image(ref, dtype), K_step).flying_pixels == 8


def test_small_mixing_within_the_tolerance_is_not_flying(dtype):
    ref, K_step = step()
    near_side = ref.copy()
    near_side[:, 9] = 5.08                      # 0.08 m off the 5 m side: below max(0.1 m, 2 % of 5 m)
    near_side[:, 10] = 9.85                     # 0.15 m off the 10 m side: below 2 % of 10 m = 0.2 m
    assert surface_errors(image(near_side, dtype), image(ref, dtype), K_step).flying_pixels == 0
    near_side[:, 10] = 9.7                      # 0.3 m off: flying
    assert surface_errors(image(near_side, dtype), image(ref, dtype), K_step).flying_pixels == 8


def test_thresholds_are_settings():
    ref, K_step = step()
    mixed = ref.copy()
    mixed[:, 9] = 6.0
    wide = SurfaceSettings(flying_min_m=1.5)
    assert surface_errors(mixed, ref, K_step).flying_pixels == 8
    assert surface_errors(mixed, ref, K_step, wide).flying_pixels == 0
    assert surface_errors(ref, ref, K_step, SurfaceSettings(edge_radius_px=0)).edge_pixels == 2 * 8
    assert surface_errors(ref, ref, K_step, SurfaceSettings(edge_jump=1.5)).edge_pixels == 0


def test_depth_edges_ignore_holes():
    depth = torch.tensor([[[[5.0, 5.0, 0.0, 5.0, 10.0]]]])
    edges = depth_edges(depth, depth > 0)
    assert edges[0, 0, 0].tolist() == [False, False, False, True, True]


def test_shapes_and_types_checked_on_entry():
    ref = plane_depth(N1, P0)
    with pytest.raises(DcslamError, match="expected \\(H, W\\)"):
        surface_errors(ref[None], ref[None], K)
    with pytest.raises(DcslamError, match="differ in shape"):
        surface_errors(ref[:, :-1], ref, K)
    with pytest.raises(DcslamError, match="floating point"):
        surface_errors(ref.astype(np.int32), ref, K)
    with pytest.raises(DcslamError, match="K has shape"):
        surface_errors(ref, ref, K[:2])
    with pytest.raises(DcslamError, match="normal searches"):
        SurfaceSettings(search=0)


def test_float32_and_float64_agree():
    axis = np.cross(N1, [0.0, 1.0, 0.0])
    N2 = Rotation.from_rotvec(0.2 * axis / np.linalg.norm(axis)).apply(N1)
    scored, ref = holes(plane_depth(N2, P0), 0.1, 3), plane_depth(N1, P0)
    e32 = surface_errors(scored.astype(np.float32), ref.astype(np.float32), K)
    e64 = surface_errors(scored, ref, K)
    assert e32.normal_mean_deg == pytest.approx(e64.normal_mean_deg, abs=1e-3)
    assert e32.p2p_mean_m == pytest.approx(e64.p2p_mean_m, abs=1e-5)
    assert e32.normal_pixels == e64.normal_pixels


def test_normals_are_those_slam_takes():
    from dcslam.slam.frame import FrameSettings, prepare_frame

    rng = np.random.default_rng(4)
    dense = holes(plane_depth(N1, P0) + 0.05 * rng.standard_normal((H, W)), 0.1, 5)
    sparse = np.where(np.arange(H)[:, None] % 6 == 0, dense, 0)     # scan lines six rows apart
    for depth, search in ((dense, 1), (sparse, 8)):
        d = torch.as_tensor(depth, dtype=torch.float32)
        frame = prepare_frame(d, torch.as_tensor(K), settings=FrameSettings(normal_search=search))
        surface = depth_surface(d[None, None], torch.as_tensor(K), search=search)
        assert torch.equal(surface.has_normal[0, 0], frame.valid)
        assert torch.equal(surface.normals[0].permute(1, 2, 0), frame.normal)


def test_mean_over_images_skips_undefined_values():
    a = SurfaceErrors(2.0, 1.0, 0.5, 0.7, math.nan, 10, 10, 0, 0)
    b = SurfaceErrors(4.0, 3.0, 1.5, 1.7, 0.25, 20, 20, 8, 2)
    m = mean_surface_errors([a, None, b])
    assert (m.normal_mean_deg, m.normal_median_deg, m.p2p_mean_m) == (3.0, 2.0, 1.0)
    assert m.flying_share == 0.25 and m.edge_pixels == 8 and m.normal_pixels == 30
    with pytest.raises(DcslamError, match="no image"):
        mean_surface_errors([None])
