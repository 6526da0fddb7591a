"""What an output was made from: input identities recorded relative to the record, checked exactly (SHA-256), and
records that are malformed or hold none passing as "nothing to check"."""
import json
import shutil

import pytest

from dcslam.errors import DcslamError
from dcslam.io.lineage import MADE_FROM, changed_inputs, check_layer_folder, check_made_from, file_hash, made_from


def test_a_record_round_trips_and_survives_moving_the_workspace(tmp_path):
    ws = tmp_path / "ws"
    (ws / "runs" / "r").mkdir(parents=True)
    (ws / "runs" / "r" / "model.pt").write_bytes(b"weights")
    out = ws / "predictions" / "r"
    out.mkdir(parents=True)
    record = {MADE_FROM: made_from({"model": ws / "runs" / "r" / "model.pt", "none": None}, out)}
    assert record[MADE_FROM] == {"model": {"path": "../../runs/r/model.pt", "sha256": file_hash(
        ws / "runs" / "r" / "model.pt"), "bytes": 7}}
    (out / "config.json").write_text(json.dumps(record))
    assert changed_inputs(record, out) == []
    shutil.move(ws, tmp_path / "moved")
    check_layer_folder(tmp_path / "moved" / "predictions" / "r")


def test_a_changed_or_missing_input_is_named_with_the_rerun(tmp_path):
    (tmp_path / "in.h5").write_bytes(b"abcd")
    record = {MADE_FROM: made_from({"depth": tmp_path / "in.h5"}, tmp_path)}
    (tmp_path / "new.h5").write_bytes(b"abce")  # same size, other bytes, written as dcslam writes: a new file
    (tmp_path / "new.h5").replace(tmp_path / "in.h5")
    assert changed_inputs(record, tmp_path) == [("depth", tmp_path / "in.h5", "changed after it was made")]
    with pytest.raises(DcslamError, match=r"^out\.json is stale: it was made from .*in\.h5, which changed after it "
                                          r"was made; rerun `dcslam slam --force`$"):
        check_made_from(record, tmp_path, "out.json", "dcslam slam --force")
    (tmp_path / "in.h5").unlink()
    with pytest.raises(DcslamError, match="which is missing now"):
        check_made_from(record, tmp_path, "out.json", "dcslam slam --force")


@pytest.mark.parametrize("text", ['{"made_from": [1, 2]}', '{"made_from": {"x": "no entry"}}', "[]", "not json",
                                  '{"stage": "predict"}'])
def test_malformed_or_absent_records_have_nothing_to_check(tmp_path, text):
    (tmp_path / "config.json").write_text(text)
    check_layer_folder(tmp_path)
    check_layer_folder(None)


def test_a_layer_folder_names_the_command_that_remakes_it(tmp_path):
    (tmp_path / "model.pt").write_bytes(b"a")
    out = tmp_path / "predictions" / "r"
    out.mkdir(parents=True)
    record = {"stage": "predict", "settings": {"run": "r", "model": None},
              MADE_FROM: made_from({"model": tmp_path / "model.pt"}, out)}
    (out / "config.json").write_text(json.dumps(record))
    (tmp_path / "model.pt").write_bytes(b"b")
    with pytest.raises(DcslamError, match=r"rerun `dcslam predict --run r --force`$"):
        check_layer_folder(out)
