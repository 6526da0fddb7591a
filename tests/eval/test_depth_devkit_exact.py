"""Devkit-exact depth scoring (``devkit_exact=True``) against dcslam's default with its two departures."""
from pathlib import Path

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.eval.depth import depth_errors, mean_errors, score_frames
from dcslam.io.kitti import read_depth_png

SAMPLE = (Path(__file__).parents[1] / "data" / "kitti-sample" / "depth_completion" / "train"
          / "2011_09_26_drive_0001_sync" / "proj_depth")


def hand_case():
    """4x4: row 0 has one depth (5 m), row 1 none, row 2 a 2 m and a 5 cm depth, row 3 none; ground truth 10 m in the
    two left columns.

    The devkit (io_depth.h interpolateBackground, evaluate_depth.cpp depthError): row 0 → 5 5 5 5; row 2 → 2, then
    the hole between 2 and 0.05 takes min = 0.05, then 0.05 extended right; row 1 lies between rows with depth and
    stays invalid (−1); row 3 copies row 2. Scored over the 8 ground-truth pixels:
      depth errors  5 5 | 11 11 | 8 9.95 | 8 9.95            → MAE 67.9 / 8 m
      inverse       0.1 0.1 | 1.1 1.1 | 0.4 19.9 | 0.4 19.9  → iMAE 43 / 8 per m
    """
    pred = np.zeros((4, 4))
    pred[0, 1] = 5.0
    pred[2, 0], pred[2, 2] = 2.0, 0.05
    gt = np.zeros((4, 4))
    gt[:, :2] = 10.0
    return pred, gt


def test_exact_matches_the_devkit_definition_by_hand():
    pred, gt = hand_case()
    e = depth_errors(pred, gt, devkit_exact=True)
    depth_err = np.array([5, 5, 11, 11, 8, 9.95, 8, 9.95])
    inv_err = np.array([0.1, 0.1, 1.1, 1.1, 0.4, 19.9, 0.4, 19.9])
    assert e.pixels == 8 and e.coverage == pytest.approx(6 / 8)
    assert e.mae_mm == pytest.approx(1000 * 67.9 / 8)
    assert e.rmse_mm == pytest.approx(1000 * np.sqrt((depth_err ** 2).mean()))
    assert e.imae_per_km == pytest.approx(1000 * 43 / 8)
    assert e.irmse_per_km == pytest.approx(1000 * np.sqrt((inv_err ** 2).mean()))


def test_default_departs_on_the_same_case():
    """dcslam's default: 5 cm is a hole (row 2 becomes 2 2 2 2, row 3 copies it) and row 1 is left out."""
    pred, gt = hand_case()
    e = depth_errors(pred, gt)
    assert e.pixels == 6 and e.coverage == pytest.approx(6 / 8)
    assert e.mae_mm == pytest.approx(1000 * (5 + 5 + 8 + 8 + 8 + 8) / 6)
    assert e.imae_per_km == pytest.approx(1000 * (0.1 + 0.1 + 0.4 * 4) / 6)


def test_scorings_differ_on_raw_sparse_input():
    """The raw LiDAR scan of the committed KITTI frame scored as a prediction: 7 ground-truth pixels lie in rows the
    interpolation cannot reach; the devkit scores them against −1 m, which raises iRMSE by half."""
    sparse = read_depth_png(SAMPLE / "velodyne_raw/image_02/0000000005.png")
    gt = read_depth_png(SAMPLE / "groundtruth/image_02/0000000005.png")
    ours, devkit = depth_errors(sparse, gt), depth_errors(sparse, gt, devkit_exact=True)
    assert devkit.pixels == 90839 and ours.pixels == 90839 - 7
    assert ours.coverage == devkit.coverage == pytest.approx(90832 / 90839)
    assert devkit.irmse_per_km == pytest.approx(12.45, abs=0.01)
    assert ours.irmse_per_km == pytest.approx(8.04, abs=0.01)
    assert devkit.imae_per_km == pytest.approx(4.33, abs=0.01) and ours.imae_per_km == pytest.approx(4.25, abs=0.01)
    assert devkit.mae_mm == pytest.approx(2261.1, abs=0.1) and ours.mae_mm == pytest.approx(2260.3, abs=0.1)


def test_near_zero_plateau_counts_only_in_the_exact_scoring():
    gt = np.full((3, 6), 20.0)
    pred = np.full((3, 6), 20.0)
    pred[0, :3] = 0.001                                # a network's ~1 mm output
    ours, devkit = depth_errors(pred, gt), depth_errors(pred, gt, devkit_exact=True)
    assert ours.imae_per_km == pytest.approx(0.0) and ours.pixels == 18      # filled from the 20 m neighbour
    assert devkit.imae_per_km == pytest.approx(1000 * 3 * (1000 - 0.05) / 18)


def test_dense_prediction_scores_the_same_both_ways():
    rng = np.random.default_rng(1)
    gt = np.where(rng.random((20, 30)) < 0.3, rng.uniform(5, 80, (20, 30)), 0)
    pred = rng.uniform(5, 80, (20, 30))
    assert depth_errors(pred, gt) == depth_errors(pred, gt, devkit_exact=True)


def test_empty_prediction():
    gt = np.full((2, 2), 4.0)
    assert depth_errors(np.zeros((2, 2)), gt).mae_mm == np.inf
    exact = depth_errors(np.zeros((2, 2)), gt, devkit_exact=True)      # everything against −1 m
    assert exact.mae_mm == pytest.approx(5000.0) and exact.coverage == 0.0 and exact.pixels == 4


def test_stack_and_mean():
    pred, gt = hand_case()
    per_image = score_frames(np.stack([pred, pred]), np.stack([gt, np.zeros_like(gt)]), devkit_exact=True)
    assert per_image[1] is None
    assert mean_errors(per_image).mae_mm == pytest.approx(1000 * 67.9 / 8)


def test_exact_always_interpolates():
    pred, gt = hand_case()
    with pytest.raises(DcslamError, match="always interpolates"):
        depth_errors(pred, gt, interpolate=False, devkit_exact=True)

