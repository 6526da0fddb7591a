import torch

from dcslam.slam.frame import prepare_frame
from dcslam.slam.fusion import PointFusion
from dcslam.slam.icpslam import ICPSLAM
from dcslam.slam.pointmap import PointMap, assign_voxels, render, voxel_keys, voxel_representatives
from dcslam.slam.scene import StreetScene, kitti_K, street_trajectory

H, W = 48, 160


def _cloud(points):
    p = torch.tensor(points, dtype=torch.float32)
    n = len(p)
    return PointMap(p, torch.tensor([[0.0, 0, -1]]).repeat(n, 1), torch.zeros(n, 3), torch.ones(n), torch.ones(n),
                    torch.zeros(n, dtype=torch.int64), torch.ones(n, dtype=torch.int64), voxel_keys(p, 0.1))


def test_voxel_keys_same_voxel_same_key():
    keys = voxel_keys(torch.tensor([[0.01, 0.02, 0.03], [0.09, 0.01, 0.05], [0.11, 0.0, 0.0], [-0.01, 0, 0]]), 0.1)
    assert keys[0] == keys[1] and len(set(keys.tolist())) == 3


def test_voxel_representatives_one_per_voxel_first_kept():
    pts = torch.tensor([[0.01, 0, 0], [0.05, 0, 0], [0.25, 0, 0], [0.02, 0.01, 0], [0.26, 0, 0]])
    assert voxel_representatives(pts, 0.1).tolist() == [0, 2]
    assert voxel_representatives(torch.zeros(0, 3), 0.1).numel() == 0


def test_render_nearest_point_wins_the_pixel():
    K = torch.tensor([[10.0, 0, 4.5], [0, 10.0, 4.5], [0, 0, 1]])
    view = render(_cloud([[0.0, 0, 5.0], [0.0, 0, 2.0], [0.5, 0, 2.0]]), torch.eye(4), K, 10, 10)
    assert int(view.index[4, 4]) == 1 or int(view.index[5, 5]) == 1
    assert int(view.valid.sum()) == 2


def _render_by_definition(points: torch.Tensor, K: torch.Tensor, height: int, width: int, splat: int) -> list:
    """render's index per pixel, point by point: each point in front of the camera covers the square around its own
    pixel; a pixel shows the nearest, then the one whose own pixel comes first in raster order, then the highest
    index."""
    best = {}
    for i, (x, y, z) in enumerate(points.tolist()):
        if z <= 0:
            continue
        uv = torch.tensor([K[0, 0] * x / z + K[0, 2], K[1, 1] * y / z + K[1, 2]], dtype=points.dtype)
        zz = float(torch.tensor(z, dtype=points.dtype))
        cu, cv = (int(c) for c in torch.round(uv).tolist())
        for v in range(cv - splat, cv + splat + 1):
            for u in range(cu - splat, cu + splat + 1):
                if 0 <= v < height and 0 <= u < width:
                    key = (zz, cv, cu, -i)
                    if (v, u) not in best or key < best[v, u]:
                        best[v, u] = key
    index = [[-1] * width for _ in range(height)]
    for (v, u), key in best.items():
        index[v][u] = -key[3]
    return index


def test_render_is_one_zbuffer_pass_and_a_minimum_filter():
    """The z-buffer at the points' own pixels and the minimum filter in image space give each pixel the point the
    definition gives it, ties of depth included (points on a coarse depth grid, duplicates), with squares reaching
    in from outside the image and points behind the camera."""
    g = torch.Generator().manual_seed(4)
    K = torch.tensor([[6.0, 0, 5.5], [0, 6.0, 3.5], [0, 0, 1]])
    for dtype in (torch.float32, torch.float64):
        p = torch.rand(60, 3, generator=g, dtype=torch.float64) * torch.tensor([8.0, 6.0, 5.0]) - \
            torch.tensor([4.0, 3.0, 1.0])
        p[:, 2] = torch.round(p[:, 2] * 2) / 2                  # depth ties
        p = torch.cat([p, p[:10]]).to(dtype)                    # same pixel, same depth: the higher index wins
        pm = _cloud(p.tolist()).to("cpu")
        pm = PointMap(p, pm.normals.to(dtype), pm.colors.to(dtype), pm.confidence.to(dtype), pm.radius.to(dtype),
                      pm.last_seen, pm.observations, pm.voxel_key)
        for splat in (0, 1, 2):
            view = render(pm, torch.eye(4, dtype=dtype), K.to(dtype), 8, 12, splat=splat)
            assert view.index.tolist() == _render_by_definition(p, K.to(dtype), 8, 12, splat)
            hit = view.index.clamp_min(0)
            assert torch.equal(view.vertex, torch.where(view.valid[..., None], p[hit], torch.zeros((), dtype=dtype)))
    for splat in (0, 1, 2):                      # points in one corner, and at the edges: a window of the image
        for corner in ([1.5, 1.2], [-2.2, -1.5], [3.0, -1.0]):
            p = (torch.rand(25, 3, generator=g, dtype=torch.float64) * torch.tensor([1.2, 0.8, 1.0])
                 + torch.tensor([*corner, 4.0])).float()
            p[:, 2] = torch.round(p[:, 2] * 4) / 4
            view = render(_cloud(p.tolist()), torch.eye(4), K, 8, 12, splat=splat)
            assert view.index.tolist() == _render_by_definition(p, K, 8, 12, splat)
            assert 0 < int(view.valid.sum()) < 8 * 12
    empty = render(PointMap.empty(), torch.eye(4), K, 8, 12, splat=1)
    assert not bool(empty.valid.any()) and empty.vertex.shape == (8, 12, 3)


def test_assign_voxels_reuses_existing_voxels():
    pm = _cloud([[0.01, 0, 0]])
    keys = voxel_keys(torch.tensor([[0.02, 0.0, 0.0], [1.0, 0, 0], [1.01, 0, 0]]), 0.1)
    target, new = assign_voxels(pm, keys, torch.full((3,), -1), 0.1)
    assert target.tolist() == [0, 1, 1] and new.numel() == 1


def test_assign_voxels_by_definition():
    """Frame points already matched keep their target; a free one goes to the map point of its voxel, else to the
    new slot of its voxel, new voxels numbered after the map in the order of their keys."""
    g = torch.Generator().manual_seed(5)
    map_keys = torch.randperm(40, generator=g)[:15] * 7
    pm = PointMap(torch.zeros(15, 3), torch.zeros(15, 3), torch.zeros(15, 3), torch.ones(15), torch.ones(15),
                  torch.zeros(15, dtype=torch.int64), torch.ones(15, dtype=torch.int64), map_keys)
    keys = torch.randint(0, 300, (200,), generator=g)
    keys[:50] = map_keys[torch.randint(0, 15, (50,), generator=g)]
    given = torch.where(torch.rand(200, generator=g) < 0.3, torch.randint(0, 15, (200,), generator=g), -1)
    target, new = assign_voxels(pm, keys, given, 0.1)
    free_new = sorted({k for k, t in zip(keys.tolist(), given.tolist()) if t < 0 and k not in map_keys.tolist()})
    assert new.tolist() == free_new
    for k, t, out in zip(keys.tolist(), given.tolist(), target.tolist()):
        if t >= 0:
            assert out == t
        elif k in map_keys.tolist():
            assert out == map_keys.tolist().index(k)
        else:
            assert out == 15 + free_new.index(k)
    empty, new = assign_voxels(PointMap.empty(), keys[:5], torch.full((5,), -1), 0.1)
    assert new.tolist() == sorted(set(keys[:5].tolist())) and empty.tolist() == [new.tolist().index(k)
                                                                                  for k in keys[:5].tolist()]


def _drive(frames, mapper):
    scene, K = StreetScene(0, length=frames + 40.0), kitti_K(H, W)
    T = street_trajectory(frames, step=1.0).float()
    sizes = []
    for i in range(frames):
        mapper.integrate(prepare_frame(scene.render(T[i].double(), K, H, W).float(), K), T[i])
        sizes.append(len(mapper.map))
    return sizes


def test_local_map_stays_bounded_and_global_map_keeps_everything():
    whole = PointFusion(voxel_size=0.2)
    local = PointFusion(voxel_size=0.2, window=5)
    full_sizes, local_sizes = _drive(30, whole), _drive(30, local)
    assert full_sizes[-1] > 2 * max(local_sizes[10:])            # the whole map keeps growing ...
    assert max(local_sizes[20:]) < 1.5 * max(local_sizes[8:12])   # ... the local one levels off
    assert len(local.global_map()) >= 0.9 * full_sizes[-1]
    assert local.global_map().points.device.type == "cpu"


def test_local_map_without_archive_drops_old_points():
    mapper = ICPSLAM(voxel_size=0.2, window=3, archive=False)
    _drive(12, mapper)
    assert len(mapper.archived) == 0 and len(mapper.global_map()) == len(mapper.map)
