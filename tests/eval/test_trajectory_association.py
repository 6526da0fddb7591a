"""Pairing an estimate with its reference by nearest timestamp within a tolerance (evo's associate_trajectories)."""
import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S, associate_timestamps, score_trajectory


def evo_style_pairs(t_short, t_long, max_diff):
    """The reference rule written out plainly: each stamp of the shorter list takes the argmin of the absolute
    differences to the longer list, kept when it is within max_diff."""
    pairs = []
    for i, stamp in enumerate(t_short):
        diffs = np.abs(t_long - stamp)
        j = int(np.argmin(diffs))
        if diffs[j] <= max_diff:
            pairs.append((i, j))
    return pairs


def test_default_is_evos_10_ms():
    assert EVO_MAX_TIME_DIFF_S == 0.01


def test_estimate_at_another_rate():
    t_gt = 100.0 + 0.1 * np.arange(40)              # 10 Hz reference
    t_est = 100.0 + 0.2 * np.arange(20) + 0.003     # 5 Hz estimate, 3 ms late
    a = associate_timestamps(t_est, t_gt)
    assert a.pairs == 20 and a.est_poses == 20 and a.gt_poses == 40
    np.testing.assert_array_equal(a.est_indices, np.arange(20))
    np.testing.assert_array_equal(a.gt_indices, 2 * np.arange(20))
    np.testing.assert_allclose(a.time_diffs_s, 0.003, atol=1e-9)
    assert a.summary().startswith("20 of 20 estimated poses paired with 40 reference poses")


def test_scores_the_common_poses():
    t_gt = 0.1 * np.arange(30)
    T_gt = np.tile(np.eye(4), (30, 1, 1))
    T_gt[:, 0, 3] = np.arange(30)
    t_est = 0.1 * np.arange(0, 30, 3) + 0.004
    T_est = T_gt[::3].copy()                        # a perfect estimate at a third of the rate
    a = associate_timestamps(t_est, t_gt)
    scores = score_trajectory(T_gt[a.gt_indices], T_est[a.est_indices])
    assert scores.poses == 10 and scores.localisation == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("offset_s, paired", [(0.0, 25), (0.0099, 25), (0.0101, 0), (-0.0099, 25), (0.05, 0)])
def test_offset_within_and_beyond_the_tolerance(offset_s, paired):
    t_gt = 0.1 * np.arange(25)
    if paired:
        assert associate_timestamps(t_gt + offset_s, t_gt).pairs == paired
    else:
        with pytest.raises(DcslamError, match="no estimated pose has a reference timestamp within 10 ms"):
            associate_timestamps(t_gt + offset_s, t_gt)


def test_tolerance_is_an_argument():
    t_gt = 0.1 * np.arange(10)
    assert associate_timestamps(t_gt + 0.02, t_gt, max_time_diff=0.025).pairs == 10
    with pytest.raises(DcslamError, match="within 1 ms"):
        associate_timestamps(t_gt + 0.002, t_gt, max_time_diff=0.001)


def test_partial_overlap_reports_the_count():
    t_gt = 0.1 * np.arange(20)
    t_est = 0.1 * np.arange(10, 30) + 0.001         # the second half runs past the reference's end
    a = associate_timestamps(t_est, t_gt)
    assert a.pairs == 10
    np.testing.assert_array_equal(a.est_indices, np.arange(10))
    np.testing.assert_array_equal(a.gt_indices, np.arange(10, 20))


def test_longer_estimate_walks_the_reference():
    t_gt = 0.2 * np.arange(10)
    t_est = 0.05 * np.arange(40) + 0.002
    a = associate_timestamps(t_est, t_gt)
    assert a.pairs == 10
    np.testing.assert_array_equal(a.gt_indices, np.arange(10))
    np.testing.assert_array_equal(a.est_indices, 4 * np.arange(10))


@pytest.mark.parametrize("seed", range(5))
def test_same_pairs_as_the_plain_rule(seed):
    rng = np.random.default_rng(seed)
    t_gt = np.cumsum(rng.uniform(0.02, 0.15, 60))
    t_est = np.sort(rng.choice(t_gt, 25, replace=False) + rng.normal(0, 0.01, 25))
    t_est = t_est[np.concatenate([[True], np.diff(t_est) > 0])]
    for t_e, t_g in ((t_est, t_gt), (t_gt, t_est)):   # estimate shorter, then longer
        a = associate_timestamps(t_e, t_g, max_time_diff=0.008)
        if len(t_e) > len(t_g):
            expected = [(j, i) for i, j in evo_style_pairs(t_g, t_e, 0.008)]
        else:
            expected = evo_style_pairs(t_e, t_g, 0.008)
        assert list(zip(a.est_indices.tolist(), a.gt_indices.tolist())) == expected


@pytest.mark.parametrize("t_est, t_gt, message", [
    ([], [0.0, 1.0], "expected \\(N,\\) with N > 0"),
    ([0.0, 0.0], [0.0, 1.0], "not strictly increasing"),
    ([0.0, np.nan], [0.0, 1.0], "not all finite"),
    ([0.0, 1.0], [[0.0, 1.0]], "reference timestamps have shape"),
])
def test_bad_timestamps(t_est, t_gt, message):
    with pytest.raises(DcslamError, match=message):
        associate_timestamps(np.array(t_est), np.array(t_gt))


def test_negative_tolerance():
    with pytest.raises(DcslamError, match="max_time_diff"):
        associate_timestamps(np.arange(3.0), np.arange(3.0), max_time_diff=-1)
