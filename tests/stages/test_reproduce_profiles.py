"""The profiles and recipes of dcslam reproduce are typed: a misspelt or mistyped option fails when the profile is
made (at import), and every profile builds every stage configuration it will run."""
import pytest

from dcslam.errors import DcslamError
from dcslam.stages.experiments import beams as reproduce_beams
from dcslam.stages.experiments.beams import BeamsProfile
from dcslam.stages.experiments.common import train_options
from dcslam.stages.experiments.table_5_2 import POSE_RECIPES, PROFILES, RECIPES, Profile
from dcslam.stages.train import TrainStageConfig


def test_a_misspelt_or_mistyped_profile_option_fails_when_the_profile_is_made():
    with pytest.raises(DcslamError, match="profile bad: train: .*no option 'epoch'; did you mean 'epochs'"):
        Profile(name="bad", drives=3, frames=12, train={"epoch": 1}, slam_frames=2)
    with pytest.raises(DcslamError, match="profile bad: slam: .*no option 'iteration'"):
        Profile(name="bad", drives=3, frames=12, train={}, slam_frames=2, slam={"iteration": 3})
    with pytest.raises(DcslamError, match="profile bad: pose: .*pose_max_sources must be int"):
        Profile(name="bad", drives=3, frames=12, train={}, slam_frames=2, pose={"pose_max_sources": 2.5})
    with pytest.raises(DcslamError, match="sets loss, which the recipes or runs set"):
        Profile(name="bad", drives=3, frames=12, train={"loss": "mse"}, slam_frames=2)
    with pytest.raises(DcslamError, match="seeds must be >= 1"):
        Profile(name="bad", drives=3, frames=12, train={}, slam_frames=2, seeds=0)
    train = dict(PROFILES["smoke"].train)
    beams = {run: dict(reproduce_beams.PROFILES["smoke"].train[run]) for run in reproduce_beams.TRAINED}
    beams["nconv"]["corect_fill"] = True
    with pytest.raises(DcslamError, match="train\\['nconv'\\]: .*did you mean 'correct_fill'"):
        BeamsProfile(name="bad", drives=3, frames=12, slam_frames=2, train=beams)
    assert Profile(name="fine", drives=3, frames=12, train=train, slam_frames=2).train == PROFILES["smoke"].train


def test_recipes_are_options_of_dcslam_train():
    for recipe in {**RECIPES, **POSE_RECIPES}.values():
        assert recipe.config is TrainStageConfig
    with pytest.raises(DcslamError, match="no option 'maks'; did you mean 'mask'"):
        train_options(loss="mse", maks="sparse")


@pytest.mark.parametrize("name", list(PROFILES))
def test_every_profile_builds_every_training_configuration_of_every_seed(name):
    profile = PROFILES[name]
    for k in range(3):
        for recipe in {**RECIPES, **POSE_RECIPES}:
            config = profile.train_config(recipe, seed=5, k=k)
            assert config.seed == 5 + k and config.name == (recipe if k == 0 else f"{recipe}-s{k}")
            source = {**RECIPES, **POSE_RECIPES}[recipe].get("init")
            assert config.init == (None if source is None else source if k == 0 else f"{source}-s{k}")
    beams = reproduce_beams.PROFILES[name]
    for run in reproduce_beams.TRAINED:
        config = beams.train_config(run, seed=0, k=1)
        assert config.name == f"{run}-s1" and config.seed == 1
        assert config.init in (None, f"{beams.train[run].get('init')}-s1")


def test_the_study_profile_is_three_seeds_over_eight_test_drives_at_64_16_8_beams():
    study, beams = PROFILES["study"], reproduce_beams.PROFILES["study"]
    assert study.seeds >= 3 and study.split[2] >= 8 and sum(study.split) == study.drives
    assert beams.seeds >= 3 and beams.split == study.split and tuple(beams.beams) == (64, 16, 8)
