"""Stage configurations: declared once, written as TOML, read back (TOML / YAML), and checked on the way in."""
import dataclasses
import sys
from pathlib import Path

import pytest

from dcslam.errors import DcslamError
from dcslam.slam.config import SlamSettings
from dcslam.stages import demo_icl, filter as filter_stage, predict, prepare, prepare_tum, reproduce, score, slam
from dcslam.stages import synth, train
from dcslam.stages.config import from_mapping, options_of, read_config_file, to_dict, to_toml

CONFIGS = [synth.SynthConfig(drives=2, out=Path("/tmp/k")), prepare.PrepareConfig(max_frames=3),
           prepare_tum.PrepareTumConfig(intrinsics="481.2,-480,319.5,239.5"),
           train.TrainStageConfig(loss="chamfer", map_frames=8, name="x"),
           predict.PredictConfig(model="ip-basic", drive=[Path("a.h5")]),
           filter_stage.FilterConfig(filters=["range:min=1", "edges"], depth="dense"),
           slam.SlamStageConfig(odometry="gt", drive=["d"], frames=3),
           score.ScoreDepthConfig(layer="dense", raw=True), score.ScoreTrajectoryConfig(layer="dense"),
           score.ScoreMapConfig(layer="x"), score.ScoreTablesConfig(drive=["d"]),
           demo_icl.DemoIclConfig(steps=3), reproduce.ReproduceConfig(profile="smoke", seed=2)]


@pytest.mark.parametrize("config", CONFIGS, ids=lambda c: type(c).__name__)
def test_toml_round_trip(config, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(to_toml(config, "title"))
    assert from_mapping(type(config), read_config_file(path), str(path)) == config


@pytest.mark.parametrize("text, message", [
    ("frames = ", "not valid TOML"), ("frame = 3", "unknown key 'frame'"), ("frames = 'x'", "must be int"),
    ("drive = 'd'", "must be a list"), ("odometry = 'ekf'", "odometry = 'ekf' is not one of gt, icp, gradicp"),
    ("frames = -1", "frames"),
    ("out = 3", "must be a path"), ("[table]\nfoo = 1", "unknown key 'table'")])
def test_malformed_config_files_fail_with_one_line(text, message, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(DcslamError, match=message):
        from_mapping(slam.SlamStageConfig, read_config_file(path), str(path))


def test_missing_file_and_yaml_without_pyyaml(tmp_path, monkeypatch):
    with pytest.raises(DcslamError, match="not found"):
        read_config_file(tmp_path / "none.toml")
    path = tmp_path / "c.yaml"
    path.write_text("frames: 3\n")
    monkeypatch.setitem(sys.modules, "yaml", None)  # PyYAML is optional: without it, one clear line
    with pytest.raises(DcslamError, match="PyYAML"):
        read_config_file(path)


def test_yaml_is_read_when_pyyaml_is_installed(tmp_path, monkeypatch):
    class FakeYaml:  # the part of PyYAML's interface that is used
        YAMLError = ValueError

        @staticmethod
        def safe_load(text):
            return dict(line.split(": ") for line in text.splitlines()) | {"frames": 3}

    monkeypatch.setitem(sys.modules, "yaml", FakeYaml)
    path = tmp_path / "c.yml"
    path.write_text("depth: sparse\n")
    assert from_mapping(slam.SlamStageConfig, read_config_file(path)) == slam.SlamStageConfig(depth="sparse", frames=3)


def test_every_slam_setting_is_a_slam_stage_option():
    options = {f.name for f in options_of(slam.SlamStageConfig)}
    assert {f.name for f in dataclasses.fields(SlamSettings)} <= options
    config = slam.SlamStageConfig(mapper="icpslam", iterations=3)
    assert config.settings() == SlamSettings(mapper="icpslam", iterations=3)


def test_validation_happens_when_the_config_is_made():
    with pytest.raises(DcslamError, match="unknown --loss"):
        train.TrainStageConfig(loss="l1")
    with pytest.raises(DcslamError, match="scale"):
        train.TrainStageConfig(scale=0.3)
    with pytest.raises(DcslamError, match="--run NAME or --model"):
        predict.PredictConfig()
    with pytest.raises(DcslamError, match="unknown filter 'median'"):
        filter_stage.FilterConfig(filters=["median"], depth="dense")
    with pytest.raises(DcslamError, match="needs --run"):
        filter_stage.FilterConfig(filters=["edges"], depth="predicted")
    with pytest.raises(DcslamError, match="four numbers"):
        prepare_tum.PrepareTumConfig(intrinsics="1,2")
    with pytest.raises(DcslamError, match="unknown profile"):
        reproduce.ReproduceConfig(profile="huge")


def test_unset_fields_are_comments_and_paths_are_strings():
    text = to_toml(predict.PredictConfig(run="r", output=Path("/x")))
    assert "# model = (unset)" in text and 'output = "/x"' in text
    assert to_dict(predict.PredictConfig(run="r", drive=[Path("a.h5")]))["drive"] == ["a.h5"]


def test_train_choices_come_from_the_registries():
    from dcslam.depth import config, losses, recipes
    from dcslam.depth.models import ARCHITECTURES

    assert config.MODELS == tuple(ARCHITECTURES)
    assert config.MASKS is recipes.MASKS is losses.MASKS and config.LOSSES is recipes.LOSSES


def test_options_are_checked_against_the_config_fields_when_made():
    from dcslam.stages.config import Options
    from dcslam.stages.train import TrainStageConfig

    options = Options(TrainStageConfig, {"loss": "chamfer"}, map_frames=8)
    assert dict(options) == {"loss": "chamfer", "map_frames": 8} and options.config is TrainStageConfig
    with pytest.raises(DcslamError, match="no option 'max_frame'; did you mean 'max_frames'"):
        Options(TrainStageConfig, max_frame=2)
    with pytest.raises(DcslamError, match="epochs must be int"):
        Options(TrainStageConfig, epochs="2")
    with pytest.raises(DcslamError, match="input_mix must be a list"):
        Options(TrainStageConfig, input_mix="sparse")
    with pytest.raises(DcslamError, match="no option 'bogus'"):
        options | {"bogus": 1}  # what is merged in is checked too
    merged = options | {"map_frames": 1, "epochs": 3}
    assert merged["map_frames"] == 1 and options["map_frames"] == 8  # a new Options; the first unchanged
    built = merged.build(name="x", seed=4)
    assert (built.loss, built.map_frames, built.epochs, built.name, built.seed, built.lr) == (
        "chamfer", 1, 3, "x", 4, TrainStageConfig().lr)
    with pytest.raises(AttributeError):
        options.config = None
