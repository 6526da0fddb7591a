import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.geometry.camera import backproject
from dcslam.geometry.normals import _grid_normals, _scan_line_normals, vertex_normals

K = torch.tensor([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]], dtype=torch.float64)


def _plane_depth(normal, offset, H=24, W=32, dtype=torch.float64):
    """Depth of the plane n . p = offset seen by K."""
    v, u = torch.meshgrid(torch.arange(H, dtype=dtype), torch.arange(W, dtype=dtype), indexing="ij")
    rays = torch.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], torch.ones_like(u)], -1)
    n = torch.tensor(normal, dtype=dtype)
    return (offset / (rays @ n))[None, None]


class TestVertexNormals:
    def test_plane_known_answer(self, device, dtype):
        n = torch.tensor([0.3, -0.4, -1.0], dtype=torch.float64)
        n = n / n.norm()
        depth = _plane_depth(n.tolist(), -5.0).to(device, dtype)
        normals, valid = vertex_normals(backproject(depth, K.to(device, dtype)))
        assert valid.all() and normals.device.type == device.type and normals.dtype == dtype
        tol = 1e-4 if dtype == torch.float32 else 1e-9
        torch.testing.assert_close(normals[0].permute(1, 2, 0).reshape(-1, 3),
                                   n.to(device, dtype).expand(24 * 32, 3), atol=tol, rtol=0)

    def test_dense_shortcut_matches_the_scan_line_path(self):
        """search = 1 takes each pixel's neighbours by shifting the grid; without holes the scan-line path with a
        wider search finds the same (adjacent) neighbours, so both must give the same bits, depth edges included."""
        g = torch.Generator().manual_seed(0)
        for dtype in (torch.float32, torch.float64):
            depth = 3 + torch.rand(2, 1, 13, 17, generator=g, dtype=torch.float64).to(dtype)
            depth[..., 5:, 9:] += 6.0                 # depth edges that the relative-gap test must not cross
            vertex = backproject(depth, K.to(dtype))
            grid, grid_ok = vertex_normals(vertex, search=1)
            lines, lines_ok = vertex_normals(vertex, search=2)
            assert torch.equal(grid_ok, lines_ok) and torch.equal(grid, lines)
            assert grid_ok.any() and not grid_ok.all()  # the edges left pixels without a normal

    def test_grid_pass_matches_the_scan_line_path_with_holes(self):
        """The one-pass grid path (masks instead of torch.where, views into one padded copy) gives the scan-line
        path's bits at search = 1 with holes, depth edges, image borders and a nearly degenerate column; their
        gradients agree to float rounding (the sums run in another order)."""
        g = torch.Generator().manual_seed(1)
        for dtype, tol in ((torch.float32, 1e-6), (torch.float64, 1e-14)):
            depth = 3 + torch.rand(2, 1, 19, 23, generator=g, dtype=torch.float64)
            depth[..., 7:, 11:] += 6.0
            depth[torch.rand(depth.shape, generator=g) < 0.25] = 0
            depth[..., :, 0] = 1.0 + 1e-9 * torch.arange(19, dtype=torch.float64)
            vertex = backproject(depth.to(dtype), K.to(dtype)).requires_grad_()
            valid = vertex.detach()[:, 2:3] > 0
            grid, grid_ok = _grid_normals(vertex, valid, 0.1)
            lines, lines_ok = _scan_line_normals(vertex, valid, 1, 0.1)
            assert torch.equal(grid_ok, lines_ok) and torch.equal(grid, lines)
            assert 0 < int(grid_ok.sum()) < int(valid.sum())
            w = torch.randn(grid.shape, generator=g, dtype=torch.float64).to(dtype)
            g_grid, = torch.autograd.grad((grid * w).sum(), vertex)
            g_lines, = torch.autograd.grad((lines * w).sum(), vertex)
            assert float((g_grid - g_lines).abs().max()) <= tol * float(g_lines.abs().max())

    def test_faces_camera(self):
        depth = torch.full((2, 1, 8, 9), 3.0, dtype=torch.float64)
        normals, _ = vertex_normals(backproject(depth, K))
        assert (normals[:, 2] < 0).all()

    def test_depth_edge_not_crossed(self):
        depth = torch.full((1, 1, 10, 12), 2.0, dtype=torch.float64)
        depth[..., 6:] = 8.0                       # two fronto-parallel planes meeting at a depth edge
        normals, valid = vertex_normals(backproject(depth, K))
        assert valid.all()
        expected = torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64)
        torch.testing.assert_close(normals[0].permute(1, 2, 0).reshape(-1, 3), expected.expand(120, 3),
                                   atol=1e-12, rtol=0)

    def test_holes_and_isolated_pixels(self):
        depth = torch.zeros(1, 1, 10, 12, dtype=torch.float64)
        depth[0, 0, 5, 5] = 3.0
        normals, valid = vertex_normals(backproject(depth, K))
        assert not valid.any() and (normals == 0).all() and torch.isfinite(normals).all()

    def test_sparse_scan_lines_need_search(self):
        n = torch.tensor([0.0, -1.0, -0.5], dtype=torch.float64)
        n = n / n.norm()
        depth = _plane_depth(n.tolist(), -2.0)
        mask = torch.zeros_like(depth, dtype=torch.bool)
        mask[..., 1::4, ::2] = True
        sparse = torch.where(mask, depth, torch.zeros_like(depth))
        _, valid_near = vertex_normals(backproject(sparse, K), search=1)
        normals, valid = vertex_normals(backproject(sparse, K), search=4)
        assert not valid_near.any()
        assert valid.sum() == mask.sum()
        torch.testing.assert_close(normals[0].permute(1, 2, 0)[mask[0, 0]], n.expand(int(mask.sum()), 3))

    def test_gradcheck(self):
        depth = (torch.rand(1, 1, 5, 6, dtype=torch.float64) * 0.1 + 2).requires_grad_()
        assert torch.autograd.gradcheck(lambda d: vertex_normals(backproject(d, K))[0], (depth,))

    def test_gradcheck_grid_with_holes_and_edges(self):
        depth = torch.rand(1, 1, 6, 7, dtype=torch.float64, generator=torch.Generator().manual_seed(2)) * 0.1 + 2
        depth[..., 3:, 4:] += 1.0                       # a depth edge the normals must not cross
        depth[..., 2, 2] = 0                            # a hole
        depth.requires_grad_()
        valid = depth.detach() > 0
        assert torch.autograd.gradcheck(lambda d: vertex_normals(backproject(d, K), valid)[0], (depth,))

    def test_errors(self):
        with pytest.raises(DcslamError, match=r"\(B, 3, H, W\)"):
            vertex_normals(torch.zeros(1, 2, 4, 4))
        with pytest.raises(DcslamError, match="search"):
            vertex_normals(torch.zeros(1, 3, 4, 4), search=0)
        with pytest.raises(DcslamError, match="bool"):
            vertex_normals(torch.zeros(1, 3, 4, 4), torch.ones(1, 1, 4, 4))


class TestSparseScanLines:
    def _rows(self, row_step, col_step):
        n = torch.tensor([0.2, -0.9, -0.4], dtype=torch.float64)
        n = n / n.norm()
        depth = _plane_depth(n.tolist(), -5.0, H=60, W=40)
        mask = torch.zeros_like(depth, dtype=torch.bool)
        mask[..., 2::row_step, ::col_step] = True
        return depth * mask, n

    def test_rows_far_apart_are_found_within_search(self):
        depth, n = self._rows(row_step=20, col_step=3)
        normals, valid = vertex_normals(backproject(depth, K), search=24)
        assert int(valid.sum()) == int((depth > 0).sum())
        torch.testing.assert_close(normals[0].permute(1, 2, 0)[valid[0, 0]], n.expand(int(valid.sum()), 3),
                                   atol=1e-9, rtol=0)

    def test_rows_beyond_search_give_no_normal(self):
        depth, _ = self._rows(row_step=20, col_step=3)
        _, valid = vertex_normals(backproject(depth, K), search=8)
        assert not valid.any()

    def test_gradcheck_sparse(self):
        depth, _ = self._rows(row_step=4, col_step=3)
        depth = depth[..., :20, :12].clone().requires_grad_()
        mask = depth.detach() > 0

        def normals(d):
            return vertex_normals(backproject(d, K), mask, search=6)[0]

        assert torch.autograd.gradcheck(normals, (depth,), eps=1e-7, atol=1e-6)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_choose_is_where_bit_for_bit(dtype):
    """choose selects torch.where's bits (signed zeros, infinities and NaNs included) under broadcasting, from strided
    views, with a graph (torch.where itself, gradients included) and without one (integer masks)."""
    from dcslam.geometry.normals import choose

    g = torch.Generator().manual_seed(5)
    a = torch.randn(2, 3, 9, 12, generator=g, dtype=dtype)
    a[0, 0, 0, :4] = torch.tensor([-0.0, float("inf"), float("nan"), -float("inf")], dtype=dtype)
    wide = torch.randn(2, 3, 9, 14, generator=g, dtype=dtype)
    b = wide[..., 1:-1]                                                # a strided view
    cond = torch.rand(2, 1, 9, 12, generator=g) < 0.5
    bits = {torch.float32: torch.int32, torch.float64: torch.int64}[dtype]
    pairs = ((a, b), (b, a), (a, torch.zeros((), dtype=dtype)), (torch.full((), -0.0, dtype=dtype), b))
    for c, (x, y) in [(cond, pair) for pair in pairs] + [(cond.expand(2, 3, 9, 12), (a[:, :1], b[:1, :1]))]:
        got, expected = choose(c, x, y), torch.where(c, x, y)
        assert got.dtype == dtype and got.shape == expected.shape
        assert torch.equal(got.view(bits), expected.view(bits))
    x = a.clone().requires_grad_()
    choose(cond, x, b).sum().backward()
    assert torch.equal(x.grad, cond.expand_as(x).to(dtype))
