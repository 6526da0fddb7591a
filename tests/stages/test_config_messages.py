"""Errors from below the command line name the file or option they are about, in one line."""
import pytest
import torch

from dcslam.depth.models import build_model, load_model, save_model
from dcslam.errors import DcslamError
from dcslam.stages.config import from_mapping
from dcslam.stages.slam import SlamStageConfig


@pytest.mark.parametrize("key, value", [("odometry", "magic"), ("confidence", "often")])
def test_a_configuration_value_outside_its_choices_names_the_file(key, value):
    with pytest.raises(DcslamError) as error:
        from_mapping(SlamStageConfig, {key: value}, "run.toml")
    assert str(error.value).startswith(f"run.toml: {key} = {value!r} is not one of ")


def test_a_model_file_whose_weights_do_not_fit_is_one_line_naming_it(tmp_path):
    path = save_model(tmp_path / "model.pt", build_model("sparse-conv", channels=4), meta={"scale": 1.0})
    record = torch.load(path, weights_only=True)
    record["hparams"] = {**record["hparams"], "channels": 8}
    torch.save(record, path)
    with pytest.raises(DcslamError) as error:
        load_model(path)
    message = str(error.value)
    assert message.startswith(f"{path}: weights do not fit sparse-conv") and "size mismatch" in message
    assert "\n" not in message and "dcslam train --force" in message
