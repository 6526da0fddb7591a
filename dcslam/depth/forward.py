"""A network's prediction for a batch of drive frames (:class:`dcslam.depth.data.Batch`): the one call that
training, its validation and the pose loss share, below all of them so that none imports another for it."""
from __future__ import annotations


def run_model(model, batch):
    """The network's prediction (B, 1, h, w) for a batch: ``model(sparse, mask)``, with ``batch.rgb`` as a third
    argument when the batch carries the colour image (guided networks)."""
    mask = (batch.sparse > 0).to(batch.sparse.dtype)
    return model(batch.sparse, mask) if batch.rgb is None else model(batch.sparse, mask, batch.rgb)


def gives_confidence(model) -> bool:
    """Whether a network says how sure it is: it has ``forward_with_confidence`` (nconv) and, where it declares
    ``gives_confidence``, says so (a sparse-conv only when trained with a confidence loss)."""
    return hasattr(model, "forward_with_confidence") and bool(getattr(model, "gives_confidence", True))


def run_model_with_confidence(model, batch, use_confidence: bool = True):
    """(prediction (B, 1, h, w), confidence (B, 1, h, w) in [0, 1] or None): the confidence of networks that give
    one (:func:`gives_confidence`) when ``use_confidence``, else None."""
    if not use_confidence or not gives_confidence(model):
        return run_model(model, batch), None
    mask = (batch.sparse > 0).to(batch.sparse.dtype)
    args = (batch.sparse, mask) if batch.rgb is None else (batch.sparse, mask, batch.rgb)
    pred, confidence = model.forward_with_confidence(*args)
    return pred, confidence.clamp(0.0, 1.0)
