import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.slam.frame import SPARSE_NORMAL_SEARCH, FrameSettings, normal_search_for, prepare_frame
from dcslam.slam.scene import StreetScene, kitti_K, lidar_mask, street_trajectory

H, W = 64, 208


@pytest.fixture(scope="module")
def street():
    scene, K = StreetScene(0), kitti_K(H, W)
    return scene.render(street_trajectory(1)[0], K, H, W).float(), K


def test_sparse_scan_lines_get_normals_by_default(street):
    depth, K = street
    sparse = depth * lidar_mask(H, W, row_step=12, col_step=2)   # lines 12 px apart: beyond the old 8 px search
    auto = prepare_frame(sparse, K)
    narrow = prepare_frame(sparse, K, settings=FrameSettings(normal_search=8))
    assert SPARSE_NORMAL_SEARCH >= 12
    assert int(auto.valid.sum()) > 0.8 * int((sparse > 0).sum()) and not narrow.valid.any()


def test_normal_search_follows_density():
    assert normal_search_for(0.5) == 1
    assert normal_search_for(0.04) == normal_search_for(0.01) == SPARSE_NORMAL_SEARCH   # 64 ... 16 beams
    assert 56 <= normal_search_for(0.0055) <= 60                                        # 8 beams: twice as far
    assert normal_search_for(1e-6) == 256 and normal_search_for(0.0) == SPARSE_NORMAL_SEARCH


def test_very_sparse_scan_lines_get_normals_by_default(street):
    depth, K = street
    mask = lidar_mask(H, W, row_step=40, col_step=6)             # lines 40 px apart: beyond the 32 px search
    sparse = depth * mask
    assert float((sparse > 0).float().mean()) < 0.01
    auto = prepare_frame(sparse, K)
    fixed = prepare_frame(sparse, K, settings=FrameSettings(normal_search=SPARSE_NORMAL_SEARCH))
    assert int(auto.valid.sum()) > 0.5 * int((sparse > 0).sum()) and not fixed.valid.any()


def test_depth_range_and_shapes(street):
    depth, K = street
    frame = prepare_frame(depth, K, settings=FrameSettings(max_depth=20.0))
    assert frame.vertex.shape == (H, W, 3) and frame.normal.shape == (H, W, 3) and frame.valid.shape == (H, W)
    assert float(frame.vertex[..., 2][frame.valid].max()) <= 20.0
    with pytest.raises(DcslamError):
        prepare_frame(torch.zeros(2, 1, H, W), K)


def test_frame_maps_are_stored_point_by_point(street):
    """Odometry and fusion gather whole points from the (H, W, 3) maps: from backproject's channel-first layout
    that gather is an order of magnitude slower, so the frame keeps them point by point (same values)."""
    from dcslam.geometry.camera import backproject

    depth, K = street
    rgb = torch.rand(1, 3, H, W)
    frame = prepare_frame(depth, K, rgb)
    assert frame.vertex.is_contiguous() and frame.normal.is_contiguous() and frame.rgb.is_contiguous()
    assert torch.equal(frame.vertex, backproject(frame.depth, K)[0].permute(1, 2, 0))
    assert torch.equal(frame.rgb, rgb[0].permute(1, 2, 0))


def test_sparse_frames_are_made_at_their_pixels_with_the_grid_values(street):
    """Sparse depth is back-projected and its normals taken at the pixels in range only: the maps, the valid pixels
    and their points (valid_points) are backproject's and vertex_normals' bit for bit, the gradients equal."""
    from dcslam.geometry.camera import backproject
    from dcslam.geometry.normals import vertex_normals
    from dcslam.slam.frame import valid_points

    depth, K = street
    sparse = (depth * lidar_mask(H, W, row_step=4, col_step=2)).double().requires_grad_()
    weight = (torch.rand(H, W, generator=torch.Generator().manual_seed(0)) > 0.2).double()
    frame = prepare_frame(sparse, K, weight=weight)
    in_range = (frame.depth > 0)
    vertex = backproject(frame.depth, K)
    normal, ok = vertex_normals(vertex, in_range, search=normal_search_for(float(in_range.double().mean())))
    assert torch.equal(frame.vertex, vertex[0].permute(1, 2, 0))
    assert torch.equal(frame.normal, normal[0].permute(1, 2, 0))
    assert torch.equal(frame.valid, ok[0, 0] & (weight > 0)) and int(frame.valid.sum()) > 100
    pixels, points = valid_points(frame)
    assert torch.equal(pixels, torch.nonzero(frame.valid.reshape(-1)).squeeze(1))
    assert torch.equal(points, frame.vertex.reshape(-1, 3)[pixels])
    (grad,) = torch.autograd.grad((points * frame.normal.reshape(-1, 3)[pixels]).sum(), sparse, retain_graph=True)
    (expected,) = torch.autograd.grad((vertex[0].permute(1, 2, 0).reshape(-1, 3)[pixels]
                                       * normal[0].permute(1, 2, 0).reshape(-1, 3)[pixels]).sum(), sparse)
    # the same terms, summed in another order where a pixel serves several normals: equal to rounding
    torch.testing.assert_close(grad, expected, rtol=1e-12, atol=1e-12 * float(expected.abs().max()))
    assert bool(grad.abs().sum() > 0)


def test_a_sparse_frame_is_read_at_its_valid_pixels_only(street):
    """A SLAM step reads a sparse frame and a uint8 colour image at the valid pixels: the (H, W, 3) images stay
    deferred, and when asked for they hold what they would have held made at once (colours: the float32 quotient
    by 255); a replaced frame carries them."""
    from dataclasses import replace

    from dcslam.slam.frame import Deferred, valid_colors, valid_normals, valid_points
    from dcslam.slam.pipeline import SLAM
    from dcslam.slam.fusion import PointFusion
    from dcslam.slam.odometry import ICPOdometry

    depth, K = street
    sparse = depth * lidar_mask(H, W, row_step=4, col_step=2)
    rgb8 = torch.randint(0, 256, (H, W, 3), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    slam = SLAM(ICPOdometry(source_voxel=0.2), PointFusion())
    frames = [prepare_frame(sparse, K, rgb8.permute(2, 0, 1)) for _ in range(2)]
    for frame in frames:
        slam.step_frame(frame)
    frame = frames[1]
    assert all(isinstance(frame.__dict__[name], Deferred) for name in ("_vertex", "_normal", "_rgb"))
    eager = prepare_frame(sparse, K, rgb8.permute(2, 0, 1).float() / 255)
    pixels, points = valid_points(frame)
    assert torch.equal(valid_colors(frame), eager.rgb.reshape(-1, 3)[pixels])
    assert torch.equal(valid_normals(frame), eager.normal.reshape(-1, 3)[pixels])
    assert torch.equal(frame.rgb, eager.rgb) and frame.rgb.is_contiguous()
    assert torch.equal(frame.vertex, eager.vertex) and torch.equal(frame.normal, eager.normal)
    assert torch.equal(points, eager.vertex.reshape(-1, 3)[pixels])
    half = replace(frames[0], valid=frames[0].valid & (torch.arange(W) < W // 2))
    assert torch.equal(half.vertex, eager.vertex) and not half.cache
    dense = prepare_frame(depth, K)                                 # dense: the grid's images, read at pixels
    pixels, points = valid_points(dense)
    normals = valid_normals(dense)
    assert isinstance(dense.__dict__["_vertex"], Deferred) and isinstance(dense.__dict__["_normal"], Deferred)
    assert torch.equal(points, dense.vertex.reshape(-1, 3)[pixels]) and points.is_contiguous()
    assert torch.equal(normals, dense.normal.reshape(-1, 3)[pixels]) and normals.is_contiguous()


def test_a_replaced_frame_starts_with_an_empty_cache(street):
    """Work cached on a frame (ICP sources, surfels) is not carried to a copy with other valid pixels."""
    from dataclasses import replace

    from dcslam.slam.odometry import ICPOdometry

    depth, K = street
    frame = prepare_frame(depth, K)
    odo = ICPOdometry(source_voxel=0.5)
    full = odo.sources(frame)
    assert odo.sources(frame) is full                               # computed once
    half = replace(frame, valid=frame.valid & (torch.arange(W) < W // 2))
    assert not half.cache and odo.sources(half)[0] < full[0]
    odo.source_voxel = 0.25                                         # another voxel size: computed again
    assert odo.sources(frame)[1].shape[0] > full[1].shape[0]
