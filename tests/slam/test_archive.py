"""The map archive: points that leave the local map round-trip through its temporary file unchanged."""
from dataclasses import fields

import pytest
import torch

from dcslam.errors import DcslamError
from dcslam.slam.archive import MapArchive
from dcslam.slam.pointmap import PointMap


def _points(n: int, dtype: torch.dtype, seed: int) -> PointMap:
    g = torch.Generator().manual_seed(seed)
    f3 = lambda: torch.randn(n, 3, generator=g, dtype=dtype)  # noqa: E731
    f1 = lambda: torch.rand(n, generator=g, dtype=dtype)  # noqa: E731
    i1 = lambda: torch.randint(0, 1 << 62, (n,), generator=g)  # noqa: E731
    return PointMap(f3(), f3(), f3(), f1(), f1(), i1(), i1(), i1())


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_parts_read_back_exactly_in_append_order(dtype):
    parts = [_points(n, dtype, seed) for seed, n in enumerate((5, 0, 17, 1))]
    archive = MapArchive()
    for part in parts:
        archive.append(part)
    assert len(archive) == 23
    assert archive.nbytes == 23 * (9 + 2) * torch.empty(0, dtype=dtype).element_size() + 23 * 3 * 8
    out = archive.read()
    for f in fields(PointMap):
        expected = torch.cat([getattr(p, f.name) for p in parts])
        assert getattr(out, f.name).dtype == expected.dtype
        assert torch.equal(getattr(out, f.name), expected), f.name


def test_the_local_map_is_read_in_after_the_archive():
    """``read(then=local)``: the archived points, then the local map's (detached, on the CPU), as concatenating
    them would give, in one allocation per field."""
    parts = [_points(n, torch.float32, seed) for seed, n in enumerate((3, 9))]
    local = _points(4, torch.float32, 7)
    local = local.with_(points=local.points.clone().requires_grad_())
    archive = MapArchive()
    for part in parts:
        archive.append(part)
    out = archive.read(then=local)
    assert not out.points.requires_grad
    for f in fields(PointMap):
        expected = torch.cat([getattr(p, f.name).detach() for p in (*parts, local)])
        assert torch.equal(getattr(out, f.name), expected), f.name


def test_parts_of_different_dtypes_are_refused():
    archive = MapArchive()
    archive.append(_points(3, torch.float32, 0))
    archive.append(_points(3, torch.float64, 1))
    with pytest.raises(DcslamError, match="different dtypes"):
        archive.read()


def test_empty_and_cleared_archives_read_none():
    archive = MapArchive()
    assert archive.read() is None and len(archive) == 0
    archive.append(_points(4, torch.float32, 0))
    archive.clear()
    assert archive.read() is None and len(archive) == 0


def test_archived_points_carry_no_graph():
    pm = _points(6, torch.float64, 1)
    pm = pm.with_(points=pm.points.clone().requires_grad_())
    archive = MapArchive()
    archive.append(pm.with_(points=pm.points * 2))
    out = archive.read()
    assert not out.points.requires_grad
    assert torch.equal(out.points, 2 * pm.points.detach())


def test_truncated_archive_file_is_refused():
    archive = MapArchive()
    archive.append(_points(8, torch.float32, 2))
    archive._file.truncate(100)
    with pytest.raises(DcslamError, match="truncated"):
        archive.read()


def test_archive_imports_no_map_module():
    """archive and pointmap imported each other (pointmap at the top, archive inside read): the archive rebuilds
    the appended class from what it recorded, so no import of dcslam.slam.pointmap is left anywhere in it."""
    import ast
    import inspect

    import dcslam.slam.archive as archive_module

    tree = ast.parse(inspect.getsource(archive_module))
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    assert not any(name.startswith("dcslam.slam") for name in imported), imported


def test_parts_of_another_class_are_refused():
    from dataclasses import dataclass

    @dataclass
    class Other:
        points: torch.Tensor

        def __len__(self) -> int:
            return self.points.shape[0]

    archive = MapArchive()
    archive.append(Other(torch.ones(3, 2, dtype=torch.float16)))
    out = archive.read()
    assert type(out) is Other and out.points.dtype == torch.float16 and torch.equal(out.points, torch.ones(3, 2))
    with pytest.raises(DcslamError, match="Other parts, not PointMap"):
        archive.append(_points(2, torch.float32, 0))
