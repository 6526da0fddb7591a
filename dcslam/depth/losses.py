"""Per-pixel losses and depth error metrics. Depth is in metres and 0 means "no value" everywhere.

The thesis's published code applied its mask after ``nn.MSELoss`` had already reduced to a scalar, so the mask
masked nothing and invalid (zero) targets were trained on. Here the mask selects pixels *before* the mean, and a
pixel without a ground-truth value is never a target.
"""
from __future__ import annotations

import torch

from dcslam.depth.recipes import MASKS
from dcslam.errors import DcslamError


def _check_same(*tensors: torch.Tensor) -> None:
    shape = tensors[0].shape
    if len(shape) != 4 or shape[1] != 1:
        raise DcslamError(f"depth has shape {tuple(shape)}, expected (B, 1, H, W)")
    for t in tensors[1:]:
        if t.shape != shape:
            raise DcslamError(f"shapes differ: {tuple(t.shape)} vs {tuple(shape)}")


def supervision_mask(sparse: torch.Tensor, dense: torch.Tensor, mask: str) -> torch.Tensor:
    """Pixels that supervise training: ``dense`` = every pixel with ground truth; ``sparse`` = pixels with a sparse
    input value that also have ground truth.

    Shape:
        sparse, dense: (B, 1, H, W) metres → (B, 1, H, W) bool
    """
    _check_same(sparse, dense)
    if mask == "dense":
        return dense > 0
    if mask == "sparse":
        return (sparse > 0) & (dense > 0)
    raise DcslamError(f"unknown mask {mask!r}; expected one of {', '.join(MASKS)}")


def _masked_mean(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, per_pixel) -> torch.Tensor:
    """Mean of ``per_pixel(pred − target)`` over the pixels where ``mask`` is true and the target has a value."""
    _check_same(pred, target, mask)
    mask = mask & (target > 0)
    count = mask.sum()
    if count == 0:
        return (pred * 0).sum()
    return per_pixel(torch.where(mask, pred - target, torch.zeros_like(pred))).sum() / count


def masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of (pred − target)² over the pixels where ``mask`` is true (0 with zero gradient if none is).

    Shape:
        pred, target: (B, 1, H, W), mask: (B, 1, H, W) bool → scalar
    """
    return _masked_mean(pred, target, mask, torch.square)


def masked_l1(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of |pred − target| over the pixels where ``mask`` is true (0 with zero gradient if none is).

    Shape:
        pred, target: (B, 1, H, W), mask: (B, 1, H, W) bool → scalar
    """
    return _masked_mean(pred, target, mask, torch.abs)


#: A predicted pixel counts as placed when it lies within PointFusion's association gate of the target depth
#: (:class:`dcslam.slam.fusion.PointFusion` defaults: max(0.1 m, 2 % of the depth)): it would be fused with the
#: true surface's point, not beside it.
PLACED_ABSOLUTE_M, PLACED_RELATIVE = 0.1, 0.02


def placed(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Where ``pred`` lies within the placement gate of ``target`` (:data:`PLACED_ABSOLUTE_M`,
    :data:`PLACED_RELATIVE`), at the pixels where both have a value. Not differentiable.

    Shape: pred, target (B, 1, H, W) metres → (B, 1, H, W) bool
    """
    _check_same(pred, target)
    pred, target = pred.detach(), target.detach()
    gate = torch.clamp(PLACED_RELATIVE * target, min=PLACED_ABSOLUTE_M)
    return (pred > 0) & (target > 0) & ((pred - target).abs() <= gate)


def confidence_loss(confidence: torch.Tensor, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of a network's per-pixel confidence against whether it placed each pixel
    (:func:`placed`), over the pixels with a target; 0 with zero gradient if none has. The gradient reaches the
    confidence only: what counts as placed is a fixed function of the prediction, so this term never moves the
    depth (a network cannot earn confidence by moving its pixels).

    Shape: confidence (B, 1, H, W) in [0, 1], pred, target (B, 1, H, W) metres → scalar
    """
    _check_same(confidence, pred, target)
    valid = target > 0
    count = valid.sum()
    if count == 0:
        return (confidence * 0).sum()
    truth = placed(pred, target).to(confidence.dtype)
    eps = 1e-6  # log(0) guard: a confidence of exactly 0 or 1 costs at most -log(1e-6) ~ 13.8 per pixel
    c = confidence.clamp(eps, 1 - eps)
    per_pixel = -(truth * torch.log(c) + (1 - truth) * torch.log1p(-c))
    return torch.where(valid, per_pixel, torch.zeros_like(per_pixel)).sum() / count


class MaskedMSE:
    """The MSE training loss with the thesis's ``sparse`` or ``dense`` mask:
    ``MaskedMSE("dense")(pred, sparse, dense)``; with ``l1_weight`` > 0, plus that weight times the mean absolute
    error (metres) over the same pixels (MSE alone trades absolute error for squared error across depth edges)."""

    def __init__(self, mask: str = "dense", l1_weight: float = 0.0):
        if mask not in MASKS:
            raise DcslamError(f"unknown mask {mask!r}; expected one of {', '.join(MASKS)}")
        if not 0 <= l1_weight < float("inf"):
            raise DcslamError(f"the L1 weight must be a non-negative number, got {l1_weight}")
        self.mask, self.l1_weight = mask, float(l1_weight)

    def __call__(self, pred: torch.Tensor, sparse: torch.Tensor, dense: torch.Tensor) -> torch.Tensor:
        mask = supervision_mask(sparse, dense, self.mask)
        loss = masked_mse(pred, dense, mask)
        return loss + self.l1_weight * masked_l1(pred, dense, mask) if self.l1_weight else loss


def batch_depth_errors(pred: torch.Tensor, dense: torch.Tensor) -> dict[str, float]:
    """MSE (m²), MAE and RMSE (mm) of a batch over the pixels with ground truth, and the pixel count: the quick
    training / validation summary (for the devkit's scores of a drive see :func:`dcslam.eval.depth.depth_errors`).

    Shape:
        pred, dense: (B, 1, H, W) metres
    """
    _check_same(pred, dense)
    with torch.no_grad():
        valid = dense > 0
        n = int(valid.sum())
        if n == 0:
            return {"mse": float("nan"), "mae_mm": float("nan"), "rmse_mm": float("nan"), "pixels": 0}
        err = (pred[valid] - dense[valid]).double()
        mse = float(err.square().mean())
        return {"mse": mse, "mae_mm": float(err.abs().mean()) * 1000.0, "rmse_mm": mse ** 0.5 * 1000.0, "pixels": n}


# ------------------------------------------------------------------------------------------- geometry losses
# What ICP sees of a completion (dcslam.eval.surface): its normals, its points' distance from the true surface, and
# the points it puts between the two sides of a depth edge. Each loss compares a prediction with a reference depth
# (taken as fixed: no gradient reaches it) through the points and normals SLAM takes.


def _surfaces(pred: torch.Tensor, reference: torch.Tensor, K: torch.Tensor, mask: torch.Tensor | None,
              reference_search: int, max_relative_gap: float):
    """(prediction's surface, reference's surface, mask) after the shape checks shared by the geometry losses."""
    from dcslam.eval.surface import depth_surface

    _check_same(pred, reference)
    if mask is None:
        mask = torch.ones_like(pred, dtype=torch.bool)
    elif mask.shape != pred.shape or mask.dtype != torch.bool:
        raise DcslamError(f"mask has shape {tuple(mask.shape)} and dtype {mask.dtype}, expected "
                          f"{tuple(pred.shape)} bool")
    with torch.no_grad():
        ref = depth_surface(reference.detach(), K, reference_search, max_relative_gap)
    return depth_surface(pred, K, 1, max_relative_gap), ref, mask


def _mean_over(values: torch.Tensor, where: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """Mean of ``values`` where ``where`` holds; 0 with zero gradient (towards ``like``) where it never does."""
    count = where.sum()
    if count == 0:
        return (like * 0).sum()
    return torch.where(where, values, torch.zeros_like(values)).sum() / count


def normal_loss(pred: torch.Tensor, reference: torch.Tensor, K: torch.Tensor, mask: torch.Tensor | None = None,
                reference_search: int = 1, max_relative_gap: float = 0.1) -> torch.Tensor:
    """Mean of 1 - cos(angle between the predicted and the reference normal) over the pixels where both have a
    normal (and ``mask`` holds): 0 for the same surface orientation everywhere, 1 - cos(a) for a surface tilted by
    a. The prediction's normals are those of dense depth (adjacent pixels); ``reference_search`` as
    :func:`dcslam.geometry.normals.vertex_normals`'s ``search`` (1 for exact depth, tens of pixels for sparse).

    Shape:
        pred, reference: (B, 1, H, W) metres, 0 = none; K: (3, 3) or (B, 3, 3); mask: (B, 1, H, W) bool → scalar
    """
    return _normal_term(pred, *_surfaces(pred, reference, K, mask, reference_search, max_relative_gap))


def _normal_term(pred, surface, ref, mask) -> torch.Tensor:
    cos = (surface.normals * ref.normals).sum(1, keepdim=True)
    return _mean_over(1 - cos, surface.has_normal & ref.has_normal & mask, pred)


def point_to_plane_loss(pred: torch.Tensor, reference: torch.Tensor, K: torch.Tensor,
                        mask: torch.Tensor | None = None, reference_search: int = 1,
                        max_relative_gap: float = 0.1) -> torch.Tensor:
    """Mean squared distance (m²) of each predicted point from the reference surface at its pixel (the plane through
    the reference point with the reference normal), over the pixels with a predicted point, a reference point and
    a reference normal (and ``mask``): δ² for a surface moved by δ along its normal. Options as
    :func:`normal_loss`.

    Shape:
        pred, reference: (B, 1, H, W) metres, 0 = none; K: (3, 3) or (B, 3, 3); mask: (B, 1, H, W) bool → scalar
    """
    return _plane_term(pred, *_surfaces(pred, reference, K, mask, reference_search, max_relative_gap))


def _plane_term(pred, surface, ref, mask) -> torch.Tensor:
    distance = (ref.normals * (surface.points - ref.points)).sum(1, keepdim=True)
    return _mean_over(distance * distance, surface.has_point & ref.has_point & ref.has_normal & mask, pred)


def edge_mixing_loss(pred: torch.Tensor, reference: torch.Tensor, K: torch.Tensor, mask: torch.Tensor | None = None,
                     reference_search: int = 1, max_relative_gap: float = 0.1, edge_jump: float | None = None,
                     radius_px: int | None = None) -> torch.Tensor:
    """The flying-pixel share of :mod:`dcslam.eval.surface` made soft: the mean, over the pixels near a reference
    depth edge (within ``radius_px`` of a relative jump above ``edge_jump``; defaults those of the metric) with a
    predicted and a reference point (and ``mask``), of the squared distance (m²) of the predicted point from the
    nearer reference surface there (the nearest plane, or point where it has no normal, of the reference pixels
    within ``radius_px``: :func:`dcslam.eval.surface.nearest_surface_sq`). A point on either side
    costs nothing; a depth mixed between the sides is pulled to the nearer one (the gradient goes to that plane).
    Options as :func:`normal_loss`.

    Shape:
        pred, reference: (B, 1, H, W) metres, 0 = none; K: (3, 3) or (B, 3, 3); mask: (B, 1, H, W) bool → scalar
    """
    surfaces = _surfaces(pred, reference, K, mask, reference_search, max_relative_gap)
    return _edge_term(pred, reference, *surfaces, edge_jump, radius_px)


def _edge_term(pred, reference, surface, ref, mask, edge_jump: float | None = None,
               radius_px: int | None = None) -> torch.Tensor:
    from dcslam.eval.surface import EDGE_RADIUS_PX, EDGE_RELATIVE_JUMP, depth_edges, near, nearest_surface_sq

    edge_jump = EDGE_RELATIVE_JUMP if edge_jump is None else edge_jump
    radius_px = EDGE_RADIUS_PX if radius_px is None else radius_px
    band = (near(depth_edges(reference, ref.has_point, edge_jump), radius_px) & surface.has_point & ref.has_point
            & mask)
    if not bool(band.any()):
        return (pred * 0).sum()
    return nearest_surface_sq(surface.points, ref, band, radius_px).mean()


class GeometryTerms:
    """The geometry terms that a training loss adds (docs/training.md, "Geometry losses"): ``terms(pred, reference,
    K)`` → ``{term: value}`` of each term with a weight > 0 (:data:`dcslam.depth.recipes.GEOMETRY_TERMS`):
    ``normal`` (:func:`normal_loss`), ``plane`` (:func:`point_to_plane_loss`), ``edge`` (:func:`edge_mixing_loss`),
    each over the pixels where the reference (the training target) has a value; :meth:`weighted` sums them with
    their weights. The reference's normals are taken the way SLAM takes them (the neighbour search chosen from the
    batch's fraction of reference pixels, :func:`dcslam.slam.frame.normal_search_for`), so that a semi-dense target
    has normals across its holes."""

    def __init__(self, normal: float = 0.0, plane: float = 0.0, edge: float = 0.0):
        from dcslam.depth.recipes import GEOMETRY_TERMS

        self.weights = {}
        for term, weight in zip(GEOMETRY_TERMS, (normal, plane, edge)):
            if not 0 <= weight < float("inf"):
                raise DcslamError(f"--{term}-weight must be a non-negative number, got {weight}")
            if weight > 0:
                self.weights[term] = float(weight)

    def __bool__(self) -> bool:
        return bool(self.weights)

    def __call__(self, pred: torch.Tensor, reference: torch.Tensor, K: torch.Tensor) -> dict[str, torch.Tensor]:
        """Shape: pred, reference (B, 1, H, W) metres, 0 = none; K (3, 3) or (B, 3, 3) → {term: scalar}."""
        from dcslam.slam.frame import FrameSettings, normal_search_for

        if not self.weights:
            return {}
        _check_same(pred, reference)
        frame = FrameSettings()
        in_range = (reference >= frame.min_depth) & (reference <= frame.max_depth)
        search = normal_search_for(float(in_range.float().mean()))
        # both surfaces once, for all the terms
        surfaces = _surfaces(pred, reference, K, None, search, frame.max_relative_gap)
        terms = {"normal": lambda: _normal_term(pred, *surfaces), "plane": lambda: _plane_term(pred, *surfaces),
                 "edge": lambda: _edge_term(pred, reference, *surfaces)}
        return {term: terms[term]() for term in self.weights}

    def weighted(self, terms: dict[str, torch.Tensor]) -> torch.Tensor | float:
        """The sum of the ``terms`` (as :meth:`__call__` gives them) times their weights (0 for none)."""
        return sum((self.weights[t] * v for t, v in terms.items()), 0.0)
