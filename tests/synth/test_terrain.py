"""The ground's height field: heights and gradients around an origin in float32, and the height alone."""
import numpy as np

from dcslam.synth.terrain import Terrain


def test_around_agrees_with_the_float64_field_and_its_height_alone_is_the_same_numbers():
    terrain = Terrain.random(np.random.default_rng(4))
    rng = np.random.default_rng(5)
    x0, y0 = 312.5, -87.25
    dx, dy = rng.uniform(-80, 80, 5000).astype(np.float32), rng.uniform(-80, 80, 5000).astype(np.float32)
    h, gx, gy = terrain.around(x0, y0, dx, dy)
    x, y = x0 + dx.astype(np.float64), y0 + dy.astype(np.float64)
    np.testing.assert_allclose(h, terrain.height(x, y), atol=2e-4)
    np.testing.assert_allclose(np.stack([gx, gy]), np.stack(terrain.gradient(x, y)), atol=2e-6)
    alone = terrain.height_around(x0, y0, dx, dy)
    assert alone.dtype == np.float32 and np.array_equal(alone, h)  # the same bits: the ray cast's final check
