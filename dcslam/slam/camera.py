"""The camera as a witness of a SLAM run: each step measured again from the images, with the LiDAR's own depth.

Sparse LiDAR depth has no companion run (it *is* the measurement), and its step checks see what every 8-beam scan
shares. The camera sees the same motion through other physics: frame k's measured returns, carried into frame k+1
by a relative pose, must land on pixels of frame k+1 as bright as the ones they came from. Starting from the first
step of the trajectory it is given (the run's, or in ``dcslam slam`` its companion's, so that one camera judges every
input of a drive) and then from its own previous one (constant velocity: a run gone off cannot take it along),
Gauss-Newton on that photometric error over an image pyramid, each return weighted by Tukey's biweight (a moving
car weighs nothing), finds the pose the images agree with (:func:`camera_step`); composed step by step
(:func:`camera_trajectory`) they give the camera's trajectory, and the distance of the run's positions from it
(:func:`camera_gap`) estimates the run's error. The depth is the measured one, never a completion (whose error is
what is judged): the LiDAR's returns of frame k, metric, so the camera's trajectory has the drive's scale.

It uses data beyond the depth: the drive's colour images, which every KITTI and generated drive has. What it
measured on the calibration drives, and what it is not yet: docs/slam.md ("The camera as a witness").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from dcslam.errors import DcslamError
from dcslam.slam.health import axis_name, road_reason

#: The image pyramid: this many levels (each half the size of the one below), coarse to fine, and Gauss-Newton
#: iterations at each; the coarsest level's basin (a few pixels at an eighth of the size) holds the error of a step
#: that tracked.
LEVELS, ITERATIONS = 4, 8
#: A level's iterations stop once an update moves less than this (metres, radians).
STOP = 1e-6
#: Tukey's biweight on the grey-level residual, its width this many robust standard deviations (1.4826 times the
#: median absolute deviation of the residuals, at least ``MIN_SCALE``): residuals past it (a moving car, an
#: occlusion) weigh nothing. A Huber weight, which keeps them at a reduced weight, let a passing car pull steps
#: 0.1-0.3 m along the road (the camera's trajectory 0.5-0.7 m off over 30 frames where Tukey's is 0.01-0.05 m).
TUKEY, MIN_SCALE = 4.685, 1e-3
#: Returns further than this are not used (far returns move by less than a pixel and are the noisiest).
MAX_DEPTH_M = 60.0
#: A step needs this many returns in view, on texture (a grey-level gradient of at least ``MIN_GRADIENT`` a pixel)
#: and not weighted out, to be measured; with fewer it is taken as the run estimated it (a blank wall, a night).
MIN_RETURNS, MIN_GRADIENT = 50, 0.5 / 255
#: A step is measured only when, at its pose, the grey levels of frame k's returns and of the pixels they warp to in
#: frame k+1 correlate at least this much (Pearson, over the returns in view at the finest level): images unrelated
#: to the depth (noise, a camera that saw something else) correlate near 0 at any pose, and Gauss-Newton on them
#: converges somewhere all the same. Images of the same kind of scene can still correlate (a road image turned upside
#: down: 0.5), so this catches no relation at all, not a wrong one. Measured steps of the calibration drives (their
#: lowest 0.40): docs/slam.md.
MIN_AGREEMENT = 0.2
_GREY = (0.299, 0.587, 0.114)
_TAPS = (1 / 16, 4 / 16, 6 / 16, 4 / 16, 1 / 16)


@dataclass(frozen=True)
class CameraStep:
    """A step measured by the camera: ``T`` (4, 4) float64 maps frame k's camera coordinates to frame k+1's;
    ``covariance`` (6, 6) the first-order covariance of the twist (translation first), s^2 (J^T W J)^-1 at the
    finest level; ``returns`` how many returns weighed on texture there; ``measured`` False when too few did, or
    their grey levels did not agree (``MIN_AGREEMENT``), or their system was singular, or the pose not finite
    (``T`` is then the step it started from, ``covariance`` NaN)."""

    T: np.ndarray
    covariance: np.ndarray
    returns: int
    measured: bool


def grey_pyramid(rgb: np.ndarray) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """The grey image of ``rgb`` and its gradients at LEVELS levels, finest first: each level the one below blurred
    by a 5-tap binomial filter and taken every second pixel. Shape: rgb (H, W, 3) uint8 -> per level (image, d/du,
    d/dv), each (H_l, W_l) float32."""
    img = torch.from_numpy(np.ascontiguousarray(rgb)).float() @ torch.tensor(_GREY) / 255.0
    taps = torch.tensor(_TAPS)
    levels = []
    for level in range(LEVELS):
        if level:
            x = F.pad(img[None, None], (2, 2, 2, 2), mode="replicate")
            x = F.conv2d(F.conv2d(x, taps.view(1, 1, 1, 5)), taps.view(1, 1, 5, 1))
            img = x[0, 0, ::2, ::2].contiguous()
        dv, du = torch.gradient(img)
        levels.append((img, du, dv))
    return levels


def _sample(images: tuple[torch.Tensor, ...], u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Bilinear samples of (H, W) images at pixel coordinates u, v (n,) -> (len(images), n) float64."""
    H, W = images[0].shape
    grid = torch.stack([u / (W - 1) * 2 - 1, v / (H - 1) * 2 - 1], -1).float().view(1, 1, -1, 2)
    stack = torch.stack(images)[None]
    return F.grid_sample(stack, grid, align_corners=True, padding_mode="border")[0, :, 0].double()


def _returns(depth: np.ndarray, K: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Frame k's measured returns within MAX_DEPTH_M: camera points (n, 3) float64 and their pixels u, v (n,)."""
    from dcslam.geometry.camera import backproject_pixels

    v, u = np.nonzero((depth > 0) & (depth < MAX_DEPTH_M))
    z = torch.from_numpy(depth[v, u].astype(np.float64))
    pixels = torch.from_numpy(v * depth.shape[1] + u)
    points = backproject_pixels(z, pixels, torch.from_numpy(np.asarray(K, np.float64)), depth.shape[1])
    return points, torch.from_numpy(u.astype(np.float64)), torch.from_numpy(v.astype(np.float64))


def _level_camera(K: np.ndarray, level: int) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy at a pyramid level: level-l pixel i is the blurred full-size pixel 2^l i (every second one
    taken), so every coordinate scales by 2^-l."""
    s = 2.0 ** level
    return K[0, 0] / s, K[1, 1] / s, K[0, 2] / s, K[1, 2] / s


def _normal_equations(points, reference, T, pyramid, camera):
    """One Gauss-Newton system of the photometric error at T: (J^T W J (6, 6), J^T W r (6,), s^2, returns that
    weigh on texture, the correlation of the returns' grey levels with those they warp to), or None with fewer than
    MIN_RETURNS in view. The twist perturbs T on the left, so a point q
    moves by v + w x q."""
    fx, fy, cx, cy = camera
    image, du, dv = pyramid
    H, W = image.shape
    q = points @ T[:3, :3].T + T[:3, 3]
    z = q[:, 2].clamp_min(1e-6)
    u, v = fx * q[:, 0] / z + cx, fy * q[:, 1] / z + cy
    ok = (q[:, 2] > 0.5) & (u > 1) & (u < W - 2) & (v > 1) & (v < H - 2)
    if int(ok.sum()) < MIN_RETURNS:
        return None
    q, z, u, v = q[ok], z[ok], u[ok], v[ok]
    value, gu, gv = _sample((image, du, dv), u, v)
    r = value - reference[ok]
    width = TUKEY * max(1.4826 * float((r - r.median()).abs().median()), MIN_SCALE)
    w = torch.where(r.abs() < width, (1 - (r / width) ** 2) ** 2, torch.zeros_like(r))
    g = torch.stack([gu * fx / z, gv * fy / z, -(gu * fx * q[:, 0] + gv * fy * q[:, 1]) / z ** 2], 1)
    J = torch.cat([g, torch.cross(q, g, dim=1)], 1)
    Jw = J * w[:, None]
    s2 = float((w * r * r).sum()) / max(float(w.sum()) - 6, 1.0)
    textured = int(((w > 0) & (torch.hypot(gu, gv) >= MIN_GRADIENT)).sum())
    return Jw.T @ J, Jw.T @ r, s2, textured, _correlation(value, reference[ok])


def _correlation(a: torch.Tensor, b: torch.Tensor) -> float:
    """Pearson's correlation of two (n,) samples; 0 where either is constant."""
    a, b = a - a.mean(), b - b.mean()
    norm = float(torch.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum()) / norm if norm > 0 else 0.0


def camera_step(pyramid_from: list, pyramid_to: list, depth_from: np.ndarray, K: np.ndarray,
                T_start: np.ndarray) -> CameraStep:
    """The relative pose (frame k -> frame k+1 camera) that the images agree with, starting from ``T_start`` (the
    camera's previous step, or the step of the trajectory it started from): frame k's measured returns
    (``depth_from``, (H, W) metres, 0 where none) warped into frame k+1, Gauss-Newton on the grey-level error
    (Tukey-weighted), coarse to fine (:func:`grey_pyramid` of both frames)."""
    from dcslam.geometry.se3 import se3_exp

    depth_from = np.asarray(depth_from)
    if depth_from.shape != tuple(pyramid_from[0][0].shape) or tuple(pyramid_to[0][0].shape) != depth_from.shape:
        raise DcslamError(f"camera step: depth {depth_from.shape} and images {tuple(pyramid_from[0][0].shape)}, "
                          f"{tuple(pyramid_to[0][0].shape)} must have one size")
    points, u, v = _returns(depth_from, K)
    T = torch.as_tensor(np.asarray(T_start, np.float64)).clone()
    system = None
    for level in reversed(range(LEVELS)):
        camera = _level_camera(K, level)
        s = 2.0 ** level
        reference = _sample(pyramid_from[level][:1], u / s, v / s)[0]
        for _ in range(ITERATIONS):
            system = _normal_equations(points, reference, T, pyramid_to[level], camera)
            if system is None:
                break
            A, b = system[0], system[1]
            step = -torch.linalg.solve(A + 1e-9 * torch.eye(6, dtype=A.dtype), b)
            T = se3_exp(step) @ T
            if float(step.abs().max()) < STOP:
                break
    if (system is None or system[3] < MIN_RETURNS or system[4] < MIN_AGREEMENT or not bool(torch.isfinite(T).all())
            or float(torch.linalg.eigvalsh(system[0])[0]) <= 0):
        return CameraStep(np.asarray(T_start, np.float64), np.full((6, 6), np.nan), 0 if system is None else
                          system[3], False)
    A, _, s2, n, _ = system
    covariance = s2 * torch.linalg.pinv(A)
    return CameraStep(T.numpy(), covariance.numpy(), n, True)


def camera_trajectory(T_world_cam: np.ndarray, steps: list[CameraStep]) -> np.ndarray:
    """The camera's trajectory: its steps composed from ``T_world_cam``'s first pose (the judged run's). Shape:
    T_world_cam (N, 4, 4), steps N - 1 (step k from frame k to k+1) -> (N, 4, 4)."""
    T = np.asarray(T_world_cam, np.float64)
    out = [T[0]]
    for step in steps:
        out.append(out[-1] @ np.linalg.inv(step.T))
    return np.stack(out)


def camera_gap(T_world_cam: np.ndarray, camera: np.ndarray, steps: list[CameraStep], over_m: float = 0.0) -> dict:
    """The camera's figure of a run: how far its last position is from the camera's trajectory (``camera``, from
    :func:`camera_trajectory`), and along which axis of the first frame's camera most. Shape: T_world_cam and
    camera (N, 4, 4).

    Returns ``{"gap_m": final distance, "direction": axis name, "largest_m": largest distance over the frames,
    "from_frame": first frame past ``over_m`` (None when none is, or ``over_m`` is 0), "steps_measured": n,
    "steps": N - 1, "sigma_m": the camera's own spread at the last frame (its steps' translation standard deviations
    added as correlated errors, the rotation's times the road still to drive; first order, optimistic)}``."""
    T = np.asarray(T_world_cam, np.float64)
    delta = T[:, :3, 3] - camera[:, :3, 3]
    gaps = np.linalg.norm(delta, axis=1)
    first_axes = T[0, :3, :3]
    over = np.flatnonzero(gaps > over_m) if over_m > 0 else []
    return {"gap_m": round(float(gaps[-1]), 4), "direction": axis_name(first_axes.T @ delta[-1]),
            "largest_m": round(float(gaps.max()), 4), "from_frame": int(over[0]) if len(over) else None,
            "steps_measured": sum(s.measured for s in steps), "steps": len(steps),
            "sigma_m": round(_camera_sigma(camera, steps), 4)}


def _camera_sigma(camera: np.ndarray, steps: list[CameraStep]) -> float:
    """Standard deviation of the camera's last position (m): each measured step's translation standard deviation
    plus its rotation's times the distance still to drive, summed (correlated, as the drift bound sums them)."""
    total = 0.0
    end = camera[-1, :3, 3]
    for k, step in enumerate(steps):
        if not step.measured:
            continue
        lever = float(np.linalg.norm(end - camera[k + 1, :3, 3]))
        c = step.covariance
        total += float(np.sqrt(max(np.trace(c[:3, :3]), 0.0))) + lever * float(np.sqrt(max(np.trace(c[3:, 3:]), 0.0)))
    return total


def witness(drive, measured: str, T_world_cam: np.ndarray, first_frame: int = 0,
            progress=None) -> tuple[np.ndarray, list[CameraStep]]:
    """The camera's trajectory over ``drive`` (a :class:`dcslam.io.drive.DriveFile`) from ``first_frame``, composed
    from ``T_world_cam``'s first pose (N, 4, 4), one pose a frame: each step started from the camera's own step
    before it (from ``T_world_cam``'s step for the first, or after a step it could not measure: the run's, or its
    companion's) and measured with the drive's ``measured`` depth (``sparse``, ``sparse@8``...: the LiDAR's returns,
    never a completion).
    ``progress``, when given, is called once a step. Returns (camera trajectory (N, 4, 4), N - 1 steps)."""
    T = np.asarray(T_world_cam, np.float64)
    K = np.asarray(drive.K, np.float64)
    before = grey_pyramid(drive.rgb(first_frame))
    depth = drive.depth(measured, first_frame)
    steps: list[CameraStep] = []
    for k in range(1, len(T)):
        now = grey_pyramid(drive.rgb(first_frame + k))
        # the camera's own previous step (constant velocity) where it measured one, so that a run gone off cannot
        # take it along; the run's step for the first, which has no velocity yet
        start = steps[-1].T if steps and steps[-1].measured else np.linalg.solve(T[k], T[k - 1])
        steps.append(camera_step(before, now, depth, K, start))
        before, depth = now, drive.depth(measured, first_frame + k)
        if progress is not None:
            progress()
    return camera_trajectory(T, steps), steps


@dataclass(frozen=True)
class CameraRules:
    """When the camera's figure judges a run (calibration: docs/slam.md, "The camera as a witness").

    max_gap_m: a run that ends further than this from the camera's trajectory is suspect; one that ends within it
        is vouched for, and its own steps' reasons are overruled (:func:`merge_camera`). 0.5 m, the verdict's own
        question: the camera's trajectory ends a median 0.02 m from the truth on the calibration runs.
    min_measured: the camera judges only when it measured at least this share of the steps (the others it took as
        the run estimated them, and cannot vouch for).
    """

    max_gap_m: float = 0.5
    min_measured: float = 0.9


def judge_camera(T_world_cam: np.ndarray, camera: np.ndarray, steps: list[CameraStep],
                 rules: CameraRules = CameraRules()) -> dict:
    """The camera's verdict on a run: its figure (:func:`camera_gap`) with ``verdict`` ``agrees`` (the run ends
    within ``max_gap_m`` of the camera's trajectory), ``departs`` (suspect, with its ``reason``) or ``unmeasured``
    (fewer than ``min_measured`` of its steps measured: no verdict), and ``measured_kind`` unset (the caller's)."""
    figure = camera_gap(T_world_cam, camera, steps, rules.max_gap_m)
    record = {**figure, "max_gap_m": rules.max_gap_m, "suspect": False, "reason": None}
    if figure["steps"] and figure["steps_measured"] < rules.min_measured * figure["steps"]:
        return {**record, "verdict": "unmeasured"}
    if figure["gap_m"] > rules.max_gap_m:
        reason = (f"the camera says the run ends {figure['gap_m']:.2f} m off (mostly {figure['direction']}), past "
                  f"{rules.max_gap_m:g} m from frame {figure['from_frame']} ({figure['steps_measured']} of "
                  f"{figure['steps']} steps measured from the images)")
        return {**record, "verdict": "departs", "suspect": True, "reason": reason}
    return {**record, "verdict": "agrees"}


def merge_camera(health: dict, camera: dict) -> dict:
    """``health`` (:func:`dcslam.slam.health.summarise`, merged with its companion evidence) with the camera's
    verdict folded in: ``camera`` added; ``departs`` makes the run suspect and appends its reason; ``agrees``
    overrules the run's own step reasons (rejected and degraded steps, the drift, hold and prediction bounds: they
    move to ``overruled``), since the camera measured each step with other physics and more precisely; the road's
    reason and the companion's stay, independent witnesses the camera does not outweigh (overruling them too missed
    runs at the 0.5 m margin that they had flagged, on seeds generated for the test: docs/slam.md); ``unmeasured``
    changes nothing."""
    merged = {**health, "reasons": list(health.get("reasons", [])), "camera": camera}
    if camera["verdict"] == "departs":
        merged["suspect"] = True
        merged["reasons"].append(camera["reason"])
    elif camera["verdict"] == "agrees":
        evidence = health.get("evidence") or {}
        witnesses = {road_reason(merged["reasons"]), evidence.get("reason") if evidence.get("suspect") else None}
        kept = [r for r in merged["reasons"] if r in witnesses]
        overruled = [r for r in merged["reasons"] if r not in witnesses]
        if overruled:
            merged["overruled"] = list(health.get("overruled", [])) + overruled
        merged["reasons"], merged["suspect"] = kept, bool(kept)
    return merged
