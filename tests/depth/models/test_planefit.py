"""Plane-fit completion: local planes in inverse depth, exact on a tilted plane across rows and columns, never
mixing the two sides of a step; and as a registered completer through the predict stage."""
import numpy as np
import pytest

from dcslam.depth.models.planefit import PlaneFit, complete_planefit, half_windows
from dcslam.depth.models.scanline import complete_scanline
from dcslam.errors import DcslamError
from tests.fixtures.surfaces import H, W, beams, plane_depth, step_depth

BEAM_ROWS = range(3, H, 7)


def test_windows():
    assert half_windows(64) == [(2, 2), (4, 2), (8, 2), (16, 4), (32, 8), (64, 16)]
    assert half_windows(12) == [(2, 2), (4, 2), (8, 2), (12, 3)]


def test_tilted_plane_is_completed_exactly_across_rows_and_columns():
    """Beams that miss 40 % of the columns and a blank column: the fit fills between the beams and across the
    columns (scanline cannot fill a column without returns), every filled pixel on the plane."""
    truth = plane_depth()
    sparse = beams(truth, BEAM_ROWS, keep_columns=0.6)
    sparse[:, 30] = 0
    out = complete_planefit(sparse)
    assert out.dtype == np.float32 and out.shape == (H, W)
    filled = out > 0
    np.testing.assert_allclose(out[filled], truth[filled], rtol=2e-6)
    np.testing.assert_array_equal(out[sparse > 0], sparse[sparse > 0])
    inner = (slice(BEAM_ROWS[0] + 1, BEAM_ROWS[-1]), slice(4, W - 4))   # between beams, away from the sides
    assert filled[inner].all()
    assert (out[BEAM_ROWS[0] + 1:BEAM_ROWS[-1], 30] > 0).all() and (complete_scanline(sparse)[:, 30] == 0).all()
    assert not filled[:BEAM_ROWS[0]].any() and not filled[BEAM_ROWS[-1] + 1:].any()  # nothing extrapolated


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("slope", [0.0, 0.5, -2.0])
def test_step_edge_is_never_bridged(seed, slope):
    truth = step_depth(10.0, 20.0, slope=slope)
    sparse = beams(truth, range(1, H, 4), keep_columns=0.8, seed=seed)
    out = complete_planefit(sparse)
    filled = (out > 0) & (sparse == 0)
    assert filled.mean() > 0.2
    assert not ((out > 10.0 * (1 + 1e-6)) & (out < 20.0 * (1 - 1e-6))).any()   # no depth between the planes
    np.testing.assert_allclose(out[filled], truth[filled], rtol=1e-6)          # each pixel on its own plane


def test_two_beams_alone_are_not_one_surface():
    """A beam at 20 m over a beam at 10 m: the two lines are coplanar in (u, v, 1/z), so only a third beam could
    tell a slope from a step; with two the pixels between stay empty."""
    sparse = np.zeros((20, 30), np.float32)
    sparse[5], sparse[12] = 20.0, 10.0
    assert (complete_planefit(sparse)[6:12] == 0).all()
    sparse[19] = 1 / 0.15                 # a third beam on the sloped plane: 1/z rises by 0.05 per 7 rows
    sloped = complete_planefit(sparse)
    assert (sloped[6:12, 3:-3] > 0).all()
    np.testing.assert_allclose(1 / sloped[8, 10], 1 / 20.0 + (1 / 10.0 - 1 / 20.0) * 3 / 7, rtol=1e-5)


def test_residual_limit_rejects_a_curved_surface():
    """A curved surface (1/z quadratic in the row, 1/z = 0.1 + 0.001 (v - 20)^2, beams every 3 rows): the smallest
    window with three beams misses it by more than the default limit of 1 % of the depth (nothing filled) and less
    than 5 % (filled under that limit)."""
    v = np.arange(40, dtype=np.float64)[:, None] * np.ones((1, 24))
    truth = 1 / (0.1 + 0.001 * (v - 20) ** 2)
    sparse = beams(truth, range(0, 40, 3))
    assert (complete_planefit(sparse)[sparse == 0] == 0).all()
    assert (complete_planefit(sparse, max_relative_rms=0.05)[sparse == 0] > 0).mean() > 0.5


def test_empty_input_and_bad_options():
    assert (complete_planefit(np.zeros((16, 16), np.float32)) == 0).all()
    with pytest.raises(DcslamError, match=r"\(H, W\)"):
        complete_planefit(np.zeros((16,), np.float32))
    for bad in ({"max_half_height": 1}, {"max_relative_rms": -1.0}, {"min_returns": 3}):
        with pytest.raises(DcslamError, match=next(iter(bad))):
            PlaneFit(**bad)


def test_predict_stage_writes_the_layer(tmp_path):
    from dcslam.io.drive import DriveFile, read_layer
    from dcslam.stages.predict import PredictConfig, run
    from dcslam.workspace import Workspace
    from tests.fixtures.depth import write_workspace

    ws = Workspace(write_workspace(tmp_path / "ws", n=3))
    result = run(ws, PredictConfig(model="planefit"))
    assert result.made_by == "planefit" and result.out_dir == ws.predictions / "planefit"
    layer = read_layer(result.layers[0])
    assert layer.config["max_relative_rms"] == 0.01
    with DriveFile(ws.drives / "drive_d.h5") as drive:
        np.testing.assert_array_equal(layer.depth[1], complete_planefit(drive.depth("sparse", 1)))
    assert result.empty_share == pytest.approx(float((layer.depth == 0).mean()))
    assert layer.config["empty_share"] == pytest.approx(result.empty_share)
