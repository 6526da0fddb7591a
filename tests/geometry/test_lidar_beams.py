from pathlib import Path

import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.geometry.lidar_beams import keep_beams, laser_ids
from dcslam.io import kitti
from dcslam.synth.street.sensors import hdl64_elevations_deg
from tests.fixtures.kitti import REAL_VELODYNE_RAW as VELODYNE_RAW
from tests.fixtures.kitti import velodyne_raw_agreement

SAMPLE = Path(__file__).parents[1] / "data" / "kitti-sample"
DATE_DIR = SAMPLE / "raw" / "2011_09_26"
SCAN = DATE_DIR / "2011_09_26_drive_0001_sync" / "velodyne_points" / "data" / "0000000005.bin"


@pytest.fixture(scope="module")
def scan():
    return kitti.read_velodyne(SCAN)


def generated_scan(rng, azimuths=400):
    """Azimuth-major order (as `dcslam synth` writes), beams top to bottom, random ranges, a few returns lost."""
    elevation = np.radians(hdl64_elevations_deg())
    azimuth = np.linspace(-np.pi, np.pi, azimuths, endpoint=False)
    el, az = np.meshgrid(elevation, azimuth)  # (azimuths, 64): azimuth by azimuth
    r = rng.uniform(3, 80, el.shape)
    xyz = np.stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)], -1).reshape(-1, 3)
    laser = np.broadcast_to(np.arange(64), el.shape).ravel()
    keep = rng.random(len(xyz)) > 0.05
    return np.concatenate([xyz, np.zeros((len(xyz), 1))], 1)[keep].astype(np.float32), laser[keep]


class TestLaserIds:
    def test_real_scan_has_64_lasers_ordered_by_elevation(self, scan):
        ids = laser_ids(scan)
        assert ids.shape == (len(scan),) and set(np.unique(ids)) == set(range(64))
        counts = np.bincount(ids, minlength=64)
        assert counts.min() > 1000  # each laser sweeps the whole revolution (~1,800 returns)
        elevation = np.degrees(np.arctan2(scan[:, 2], np.hypot(scan[:, 0], scan[:, 1])))
        far = np.hypot(scan[:, 0], scan[:, 1]) > 10
        median = [np.median(elevation[far & (ids == k)]) for k in range(32)]  # the upper block sees far points
        assert np.all(np.diff(median) < 0)
        assert median[0] == pytest.approx(2.0, abs=0.6)

    def test_real_scan_elevation_clustering_agrees_with_scan_order(self, scan):
        shuffled = np.random.default_rng(0).permutation(len(scan))  # no scan order left: elevation is used
        by_elevation = laser_ids(scan[shuffled])
        by_order = laser_ids(scan)[shuffled]
        purity = np.mean([np.bincount(by_elevation[by_order == k]).max() / np.sum(by_order == k) for k in range(64)])
        assert purity > 0.95

    def test_generated_scan_known_lasers(self):
        points, laser = generated_scan(np.random.default_rng(1))
        assert np.array_equal(laser_ids(points), laser)

    @pytest.mark.parametrize("bad, match", [
        (np.zeros((100, 2)), r"\(N, 3\) or \(N, 4\)"),
        (np.full((100, 3), np.nan), "NaN"),
        (np.ones((10, 3)), "fewer than its 64 lasers"),
        (np.tile([[10.0, 0.0, 1.0]], (200, 1)), "distinct elevation"),
    ])
    def test_malformed(self, bad, match):
        with pytest.raises(DcslamError, match=match):
            laser_ids(bad)


class TestKeepBeams:
    @pytest.mark.parametrize("beams", [64, 32, 16, 8])
    def test_beam_count_of_the_result(self, scan, beams):
        kept = keep_beams(scan, beams)
        ids = laser_ids(scan)
        chosen = ids % (64 // beams) == 0
        assert np.array_equal(kept, scan[chosen])
        assert np.array_equal(np.unique(ids[chosen]), np.arange(0, 64, 64 // beams))
        assert len(kept) == pytest.approx(len(scan) * beams / 64, rel=0.1)
        if beams < 64:  # what is left is read again as a scan of `beams` lasers, one per kept laser
            assert np.array_equal(laser_ids(kept, beams), ids[chosen] // (64 // beams))

    @pytest.mark.parametrize("beams", [32, 16, 8])
    def test_generated_beam_count(self, beams):
        points, laser = generated_scan(np.random.default_rng(2))
        kept = keep_beams(points, beams)
        assert len(kept) == np.sum(laser % (64 // beams) == 0)
        assert len(laser_ids(kept, beams)) == len(kept)  # the result reads as a `beams`-laser scan
        elevation = np.degrees(np.arctan2(kept[:, 2], np.hypot(kept[:, 0], kept[:, 1])))
        nearest = np.abs(elevation[:, None] - hdl64_elevations_deg()[None]).argmin(1)
        assert np.array_equal(np.unique(nearest), np.arange(0, 64, 64 // beams))

    def test_64_beams_reproduce_velodyne_raw(self, scan):
        calib = kitti.read_calibration(DATE_DIR)
        projected = kitti.project_velodyne(keep_beams(scan, 64), calib)
        reference = kitti.read_depth_png(VELODYNE_RAW)
        ys, xs = np.nonzero(reference)
        # KITTI's velodyne_raw compensates the ego-motion within a sweep; we do not, so points move by a pixel or
        # two: 6,239 of its 19,154 pixels hold a projected point on the very pixel (6,092 within 1 %) and 95 % one
        # within 2 pixels and 2 %.
        same = (projected[ys, xs] > 0) & (np.abs(projected[ys, xs] - reference[ys, xs]) <= 0.01 * reference[ys, xs])
        assert same.sum() > 0.3 * len(ys)
        assert velodyne_raw_agreement(projected, reference) >= 0.95

    def test_fewer_beams_fewer_rows_same_values(self, scan):
        calib = kitti.read_calibration(DATE_DIR)
        full = kitti.project_velodyne(scan, calib)
        sixteen = kitti.project_velodyne(keep_beams(scan, 16), calib)
        assert 0.2 < (sixteen > 0).sum() / (full > 0).sum() < 0.3
        assert np.all(sixteen[sixteen > 0] >= full[sixteen > 0] - 1e-6)  # a subset: never nearer than the full scan

    @pytest.mark.parametrize("beams", [0, 3, 48, 128])
    def test_beams_must_divide_64(self, scan, beams):
        with pytest.raises(DcslamError, match="divisor"):
            keep_beams(scan, beams)
