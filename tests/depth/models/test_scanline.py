"""Scanline completion: inverse depth interpolated down each column between returns of one surface, exact on a
plane, never across a step; and as a registered completer through `dcslam predict`."""
import numpy as np
import pytest

from dcslam.depth.models.scanline import Scanline, complete_scanline
from dcslam.errors import DcslamError
from tests.fixtures.surfaces import H, W, beams, plane_depth, step_depth

BEAM_ROWS = range(3, H, 7)  # rows 3, 10, ..., 45: a few beams, 7 rows apart


def test_tilted_plane_is_completed_exactly_between_the_beams():
    truth = plane_depth()
    sparse = beams(truth, BEAM_ROWS)
    out = complete_scanline(sparse)
    assert out.dtype == np.float32 and out.shape == (H, W)
    between = slice(BEAM_ROWS[0], BEAM_ROWS[-1] + 1)
    assert (out[between] > 0).all()                                # every pixel between the first and last beam
    np.testing.assert_allclose(out[between], truth[between], rtol=2e-6)
    assert (out[:BEAM_ROWS[0]] == 0).all() and (out[BEAM_ROWS[-1] + 1:] == 0).all()  # nothing extrapolated
    np.testing.assert_array_equal(out[sparse > 0], sparse[sparse > 0])  # the returns unchanged
    # the same interpolation of depth instead of inverse depth misses the plane: the test can tell them apart
    r0, r1, r = BEAM_ROWS[0], BEAM_ROWS[1], BEAM_ROWS[0] + 3
    linear_depth = truth[r0] + (truth[r1] - truth[r0]) * (r - r0) / (r1 - r0)
    assert np.abs(linear_depth / truth[r] - 1).max() > 1e-4


def test_step_edge_is_never_bridged():
    truth = step_depth(10.0, 20.0)
    sparse = beams(truth, range(1, H, 4), keep_columns=0.8)
    out = complete_scanline(sparse)
    filled = out[(out > 0) & (sparse == 0)]
    assert filled.size > 0.3 * out.size
    assert not ((filled > 10.0) & (filled < 20.0)).any()           # no depth between the two planes
    np.testing.assert_array_equal(out[(out > 0)], truth[out > 0])  # every value the true one of its pixel


def test_the_threshold_decides_what_one_surface_is():
    """Returns 10 m and 10.5 m apart in depth (5 %): bridged under the default 0.1, not under 0.04."""
    sparse = np.zeros((10, 3), np.float32)
    sparse[2], sparse[7] = 10.0, 10.5
    assert (complete_scanline(sparse)[3:7] > 0).all()
    assert (complete_scanline(sparse, max_relative_step=0.04)[3:7] == 0).all()
    np.testing.assert_allclose(complete_scanline(sparse)[4, 0], 1 / (0.6 / 10.0 + 0.4 / 10.5), rtol=1e-6)


def test_gaps_longer_than_the_limit_stay_empty():
    sparse = np.zeros((40, 4), np.float32)
    sparse[2], sparse[30] = 8.0, 8.0
    assert (complete_scanline(sparse, max_gap_px=27)[3:30] == 0).all()
    np.testing.assert_allclose(complete_scanline(sparse, max_gap_px=28)[3:30], 8.0, rtol=1e-6)


def test_empty_input_gives_empty_output_and_near_or_invalid_values_are_no_return():
    assert (complete_scanline(np.zeros((12, 9), np.float32)) == 0).all()
    sparse = np.zeros((12, 2), np.float32)
    sparse[1], sparse[10] = 5.0, 5.0
    sparse[5, 0], sparse[5, 1] = 0.05, np.nan                      # below MIN_DEPTH_M, not finite: holes
    out = complete_scanline(sparse)
    np.testing.assert_allclose(out[1:11], 5.0, rtol=1e-6)


def test_bad_input_and_options():
    with pytest.raises(DcslamError, match=r"\(H, W\)"):
        complete_scanline(np.zeros((2, 3, 4), np.float32))
    with pytest.raises(DcslamError, match="max_relative_step"):
        Scanline(max_relative_step=0)
    with pytest.raises(DcslamError, match="max_gap_px"):
        Scanline(max_gap_px=1)


def test_registered_and_listed_by_predict(cli):
    from dcslam.depth.models import build_classical

    assert isinstance(build_classical("scanline"), Scanline)
    result = cli("predict", "--help")
    assert result.exit_code == 0 and "scanline" in result.output and "planefit" in result.output


def test_predict_writes_the_layer_and_its_empty_share(cli, tmp_path):
    from dcslam.io.drive import DriveFile, read_layer
    from tests.fixtures.depth import write_workspace

    ws = write_workspace(tmp_path / "ws", n=3)
    result = cli("predict", "-w", ws, "--model", "scanline")
    assert result.exit_code == 0, result.output
    layer = read_layer(ws / "predictions" / "scanline" / "drive_d.h5")
    assert layer.made_by == "scanline" and layer.config["max_relative_step"] == 0.1
    with DriveFile(ws / "drives" / "drive_d.h5") as drive:
        assert layer.depth.shape == drive.shape
        np.testing.assert_array_equal(layer.depth[0], complete_scanline(drive.depth("sparse", 0)))
    share = float((layer.depth == 0).mean())
    assert 0 < share < 1 and layer.config["empty_share"] == pytest.approx(share)
    assert f"{100 * share:.1f} % of the pixels left empty" in result.output
