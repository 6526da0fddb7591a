import numpy as np
import pytest

from dcslam.errors import DcslamError
from dcslam.filters import ConfidenceFilter, FilterChain, RangeFilter, filter_drives, filter_frames, parse_filter
from dcslam.io.drive import Layer, read_layer, write_layer
from tests.filters.test_filters import K, write_drive


def test_known_answer_and_spec():
    depth = np.array([[1.0, 2.0], [3.0, 0.0]], np.float32)
    confidence = np.array([[0.9, 0.5], [0.2, 0.8]], np.float32)
    out = parse_filter("confidence:min=0.5").apply(depth, K, confidence=confidence)
    assert out.tolist() == [[1.0, 2.0], [0.0, 0.0]]
    assert parse_filter("confidence") == ConfidenceFilter(0.5)
    assert np.array_equal(depth, [[1.0, 2.0], [3.0, 0.0]])  # the input is not modified


def test_chain_passes_confidence_only_to_the_filters_that_use_it():
    depth = np.full((1, 2, 2), 10.0, np.float32)
    confidence = np.array([[[0.1, 0.6], [0.7, 0.9]]], np.float32)
    chain = FilterChain((RangeFilter(5, 15), ConfidenceFilter(0.65)))
    assert chain.needs_confidence and not FilterChain((RangeFilter(5, 15),)).needs_confidence
    assert (filter_frames(depth, K, chain, confidence=confidence) > 0).tolist() == [[[False, False], [True, True]]]


def test_keep_holds_the_most_confident_fraction_of_the_pixels_with_depth():
    depth = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 0.0]], np.float32)
    confidence = np.array([[0.01, 0.02, 0.03], [0.04, 0.05, 0.9]], np.float32)  # the hole's confidence is ignored
    out = parse_filter("confidence:min=0,keep=0.4").apply(depth, K, confidence=confidence)
    assert out.tolist() == [[0.0, 0.0, 0.0], [4.0, 5.0, 0.0]]
    both = ConfidenceFilter(min=0.045, keep=0.4).apply(depth, K, confidence=confidence)
    assert both.tolist() == [[0.0, 0.0, 0.0], [0.0, 5.0, 0.0]]  # min and keep both apply
    assert np.array_equal(ConfidenceFilter(min=0, keep=1).apply(depth, K, confidence=confidence), depth)
    empty = np.zeros_like(depth)
    assert np.array_equal(ConfidenceFilter(min=0, keep=0.5).apply(empty, K, confidence=confidence), empty)


@pytest.mark.parametrize("make, match", [
    (lambda: ConfidenceFilter(1.5), "0 <= min <= 1"),
    (lambda: ConfidenceFilter(0.1, keep=0), "0 < keep <= 1"),
    (lambda: ConfidenceFilter().apply(np.ones((2, 2)), K), "needs a layer with confidence"),
    (lambda: ConfidenceFilter().apply(np.ones((2, 2)), K, confidence=np.ones((3, 2))), "like its depth"),
    (lambda: parse_filter("confidence:min=x"), "min"),
])
def test_bad_use(make, match):
    with pytest.raises(DcslamError, match=match):
        make()


def test_filter_drives_keeps_the_confidence_of_what_it_keeps(tmp_path):
    drive = write_drive(tmp_path / "d.h5")
    rng = np.random.default_rng(0)
    depth = rng.uniform(5, 20, (3, 8, 12)).astype(np.float32)
    confidence = rng.uniform(0, 1, (3, 8, 12)).astype(np.float32)
    write_layer(tmp_path / "pred.h5", Layer(depth, drive="d", made_by="nconv", confidence=confidence))
    chain = FilterChain((ConfidenceFilter(0.5),))
    out = tmp_path / "out" / "d.h5"
    filter_drives([(drive, tmp_path / "pred.h5", out)], chain, made_by="nconv+confidence", settings={})
    layer = read_layer(out)
    assert np.array_equal(layer.depth > 0, confidence >= 0.5)
    assert np.array_equal(layer.confidence, np.where(confidence >= 0.5, confidence, 0))
    with pytest.raises(DcslamError, match="holds no confidence"):
        filter_drives([(drive, "dense", tmp_path / "x.h5")], chain, made_by="x", settings={})
    write_layer(tmp_path / "plain.h5", Layer(depth, drive="d", made_by="sparse-conv"))
    with pytest.raises(DcslamError, match="holds no confidence"):
        filter_drives([(drive, tmp_path / "plain.h5", tmp_path / "y.h5")], chain, made_by="x", settings={})
