import pytest

from dcslam.errors import DcslamError
from dcslam.slam.association import NearestNeighbourAssociation
from dcslam.slam.config import SlamSettings, build_slam
from dcslam.slam.icpslam import ICPSLAM
from dcslam.slam.robust import AdaptiveThreshold, GemanMcClure
from dcslam.slam.solvers import DifferentiableLM


def test_every_field_has_help():
    for f in SlamSettings.__dataclass_fields__.values():
        assert f.metadata.get("help"), f.name


@pytest.mark.parametrize("kwargs", [dict(kernel="huber"), dict(gate_schedule="4,x"), dict(gate_schedule="0"),
                                    dict(source_voxel=-1), dict(local_map_frames=-1), dict(normal_search=-2),
                                    dict(reference_depth=-1), dict(odometry="orb"), dict(coarse_iterations=-1),
                                    dict(first_step_prior="gps")])
def test_bad_values_are_refused(kwargs):
    with pytest.raises(DcslamError):
        SlamSettings(**kwargs)


def test_build_slam_turns_settings_into_objects():
    slam = build_slam(SlamSettings(odometry="gradicp", mapper="icpslam", association="nn", kernel="gm",
                                   adaptive_threshold=True, gate_schedule="2,1", tolerance=1e-3, source_voxel=0.3,
                                   local_map_frames=7, keep_global_map=False, normal_search=5, coarse_iterations=4))
    odo = slam.odometry
    assert isinstance(odo.solver, DifferentiableLM) and odo.solver.tolerance == 1e-3
    assert isinstance(odo.association, NearestNeighbourAssociation)
    assert isinstance(odo.kernel, GemanMcClure) and isinstance(odo.adaptive, AdaptiveThreshold)
    assert odo.coarse_to_fine == (2.0, 1.0) and odo.source_voxel == 0.3 and odo.coarse_iterations == 4
    assert isinstance(slam.mapper, ICPSLAM) and slam.mapper.window == 7 and slam.mapper.archive is False
    assert slam.frame_settings.normal_search == 5


def test_defaults_round_trip_through_dict():
    s = SlamSettings()
    assert SlamSettings(**s.to_dict()) == s


def test_the_settings_and_the_loop_do_not_import_each_other():
    """config builds the SLAM of pipeline, so pipeline imports nothing of config, at the top or in a function."""
    import ast
    from pathlib import Path

    import dcslam.slam.pipeline as pipeline

    imported = set()
    for node in ast.walk(ast.parse(Path(pipeline.__file__).read_text())):
        if isinstance(node, ast.ImportFrom):
            imported.add(node.module)
        elif isinstance(node, ast.Import):
            imported.update(alias.name for alias in node.names)
    assert "dcslam.slam" in {m.rsplit(".", 1)[0] for m in imported if m}  # the walk sees its imports
    assert "dcslam.slam.config" not in imported
