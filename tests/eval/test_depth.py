import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.eval.depth import MIN_DEPTH_M, depth_errors, interpolate_background, mean_errors, score_drive, score_frames
from dcslam.filters import DiscontinuityFilter
from dcslam.io.drive import DriveFrame, DriveWriter, Layer, write_layer


class TestInterpolateBackground:
    def test_row_gaps_take_the_nearer_neighbour_and_ends_extend(self):
        row = np.array([[0, 2, 0, 0, 5, 0]], np.float32)
        np.testing.assert_array_equal(interpolate_background(row), [[2, 2, 2, 2, 5, 5]])

    def test_empty_rows_above_and_below_copy_the_nearest_row(self):
        depth = np.zeros((4, 3), np.float32)
        depth[1] = [1, 0, 3]
        depth[2] = [4, 4, 4]
        out = interpolate_background(depth)
        np.testing.assert_array_equal(out[0], [1, 1, 3])
        np.testing.assert_array_equal(out[3], [4, 4, 4])

    def test_does_not_modify_input(self):
        depth = np.array([[0, 1.0]], np.float32)
        interpolate_background(depth)
        assert depth[0, 0] == 0

    def test_rejects_bad_shape(self):
        with pytest.raises(DcslamError, match=r"\(H, W\)"):
            interpolate_background(np.zeros((2, 2, 2)))


class TestDepthErrors:
    def test_known_answer(self):
        gt = np.array([[10.0, 20.0, 0.0]])
        pred = np.array([[11.0, 18.0, 7.0]])
        e = depth_errors(pred, gt)
        assert e.mae_mm == pytest.approx(1500.0)
        assert e.rmse_mm == pytest.approx(1000 * np.sqrt((1 + 4) / 2))
        inv = np.array([abs(1 / 10 - 1 / 11), abs(1 / 20 - 1 / 18)])
        assert e.imae_per_km == pytest.approx(1000 * inv.mean())
        assert e.irmse_per_km == pytest.approx(1000 * np.sqrt((inv ** 2).mean()))
        assert e.pixels == 2 and e.coverage == 1.0

    def test_holes_are_interpolated_like_the_devkit(self):
        gt = np.array([[10.0, 10.0, 10.0]])
        pred = np.array([[10.0, 0.0, 12.0]])          # hole filled with min(10, 12) = 10
        e = depth_errors(pred, gt)
        assert e.mae_mm == pytest.approx(2000 / 3) and e.coverage == 1.0 and e.pixels == 3
        raw = depth_errors(pred, gt, interpolate=False)          # only the pixels with predicted depth
        assert raw.mae_mm == pytest.approx(1000.0) and raw.pixels == 2 and raw.coverage == pytest.approx(2 / 3)

    def test_unfillable_rows_are_left_out_and_empty_prediction_is_infinite(self):
        gt = np.full((3, 2), 10.0)
        pred = np.array([[11.0, 11.0], [0.0, 0.0], [12.0, 0.0]])   # middle row cannot be filled
        e = depth_errors(pred, gt)
        assert e.pixels == 4 and e.coverage == pytest.approx(4 / 6)
        assert e.mae_mm == pytest.approx(1000 * (1 + 1 + 2 + 2) / 4)
        empty = depth_errors(np.zeros((3, 2)), gt)
        assert np.isinf(empty.mae_mm) and empty.pixels == 0

    def test_depths_below_the_minimum_are_holes(self):
        """A depth no sensor measures (a network's ~1 mm output where no input reached) is no prediction: the
        devkit fill takes the smaller flanking depth, so a 1.3 mm pixel next to a hole would give the hole's
        ground-truth pixels |1/d_gt − 1/0.0013| ≈ 770 1/m."""
        gt = np.array([[10.0, 10.0, 10.0, 10.0]])
        pred = np.array([[0.0013, 0.0, 0.0, 10.0]])
        e = depth_errors(pred, gt)
        assert e.irmse_per_km == pytest.approx(0.0) and e.mae_mm == pytest.approx(0.0) and e.coverage == 1.0
        raw = depth_errors(pred, gt, interpolate=False)          # the tiny pixel is not scored at all
        assert raw.pixels == 1 and raw.coverage == pytest.approx(1 / 4) and raw.irmse_per_km == 0.0
        at_minimum = depth_errors(np.array([[MIN_DEPTH_M, 10.0]]), np.array([[10.0, 10.0]]), interpolate=False)
        assert at_minimum.pixels == 2                              # the bound itself is a depth

    def test_edges_filtered_prediction_with_a_near_zero_plateau(self):
        """The quick reproduction's chamfer-8+edges row (iRMSE 707 /km against 11 unfiltered): the trained network
        outputs a constant 0.18 mm where no LiDAR input reaches (above the scan), ramping up to the scene. The
        edges filter drops the ramp; the devkit fill then gave the holes between plateau and scene the plateau's
        depth, on pixels with ground truth (one such pixel made one frame's iRMSE 22 285 /km). Depths below
        MIN_DEPTH_M are holes, so the holes take the scene's depth."""
        h, w = 24, 40
        top = 8 + (np.arange(w) // 8) * 2                      # first scene row of each column: a staircase
        rows = np.arange(h)[:, None]
        pred = np.where(rows < top - 3, 0.0013, 10.0).astype(np.float32)
        for k, ramp in enumerate((0.05, 0.6, 4.0)):              # the network's smooth ramp into the scene
            pred[rows == top - 3 + k] = ramp
        gt = np.where(rows >= top - 1, 10.0, 0.0)               # accumulated ground truth reaches the last ramp row
        raw = depth_errors(pred, gt)
        filtered = DiscontinuityFilter().apply(pred)
        assert ((filtered > 0) & (filtered < 0.01)).any()       # the plateau survives the edges filter
        edges = depth_errors(filtered, gt)
        assert edges.coverage == 1.0
        assert edges.irmse_per_km <= raw.irmse_per_km           # removing the ramp must not make it worse

    def test_no_ground_truth(self):
        assert depth_errors(np.ones((2, 2)), np.zeros((2, 2))) is None

    def test_mean_is_per_image(self):
        a = depth_errors(np.array([[11.0]]), np.array([[10.0]]))
        b = depth_errors(np.array([[10.0, 10.0, 10.0]]), np.array([[10.0, 10.0, 10.0]]))
        mean = mean_errors([a, b, None])
        assert mean.mae_mm == pytest.approx(500.0) and mean.pixels == 4

    def test_mean_of_nothing_fails(self):
        with pytest.raises(DcslamError, match="no image"):
            mean_errors([None])

    def test_shape_mismatch_fails(self):
        with pytest.raises(DcslamError):
            score_frames(np.ones((2, 3, 4)), np.ones((3, 3, 4)))


def write_drive(path, n=3, h=8, w=12, seed=0):
    rng = np.random.default_rng(seed)
    K = np.array([[10.0, 0, w / 2], [0, 10.0, h / 2], [0, 0, 1]])
    with DriveWriter(path, K, h, w, source="synthetic", date="2011_09_26", drive=path.stem) as writer:
        for i in range(n):
            dense = rng.uniform(5, 20, (h, w)).astype(np.float32)
            sparse = np.where(rng.random((h, w)) < 0.3, dense, 0).astype(np.float32)
            T = np.eye(4)
            T[2, 3] = i
            writer.append(DriveFrame(rgb=np.zeros((h, w, 3), np.uint8), sparse=sparse, dense=dense, T_world_cam=T,
                                timestamp=0.1 * i, frame_id=i))
    return path


def test_score_drive(tmp_path):
    drive = write_drive(tmp_path / "d.h5")
    assert mean_errors(score_drive(drive, "dense")).mae_mm == 0.0
    sparse = mean_errors(score_drive(drive, "sparse"))
    assert sparse.mae_mm > 0 and sparse.coverage == 1.0
    layer = tmp_path / "layer.h5"
    write_layer(layer, Layer(depth=np.full((2, 8, 12), 7.0, np.float32), drive="d", made_by="test"))
    with pytest.raises(DcslamError, match="2 frames but its drive has 3"):
        score_drive(drive, layer)
