"""Depth-only evidence of a SLAM run's vertical drift, measured on generated drives against the truth: per run its
final error (and its vertical part), and the figures of the candidates

- ``road``: each frame's road plane (RANSAC on the returns more than 0.8 m below the camera, then least squares on
  its inliers) and, per step, the previous frame's road returns carried into the frame by the estimated relative
  pose and fitted alike: the rotation and the offset that map the previous plane onto the frame's own are that
  step's pitch/roll and height error as the road sees it. Composing the estimated steps with those corrections
  gives a road-corrected trajectory; the figure is its distance from the estimated one at the end (``road_m``) and
  the vertical part of it (``road_vertical_m``).
- ``tilt``: the angle between the world road normal of the last frame and that of the first (``tilt_deg``): pitch
  drift plus the road's own change of grade.
- ``s2s``: the run again with a local map of one frame (scan-to-scan ICP), and the distance between the two final
  positions (``s2s_m``, ``s2s_vertical_m``).

Prints per run and, per candidate, the rule "the step rules, without the drift bound, or the figure above a
threshold" (and the same with the drift bound kept over the horizontal directions, ``horizontal_bound_m``), the
threshold the largest that flags every bad run of the ``--fit-seeds`` half, and its counts on both halves.

    python benchmarks/slam_road_plane.py /tmp/evd --seeds 7171-7186 --beams 8,16 --kinds sparse,exact
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from dcslam.slam.road import align_planes

BELOW_M, NEAR_M, FAR_M, SIDE_M, INLIER_M = 0.8, 3.0, 30.0, 10.0, 0.08


def road_points(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Returns more than BELOW_M below the camera, NEAR_M-FAR_M ahead, within SIDE_M across (camera frame, y down).
    Shape: depth (H, W), K (3, 3) -> (M, 3)."""
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    p = np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z], 1)
    keep = (p[:, 1] > BELOW_M) & (p[:, 2] > NEAR_M) & (p[:, 2] < FAR_M) & (np.abs(p[:, 0]) < SIDE_M)
    return p[keep]


def fit_plane(p: np.ndarray, rng: np.random.Generator, tries: int = 200) -> tuple[np.ndarray, float, np.ndarray]:
    """RANSAC plane n.x + d = 0 (n unit, pointing up: n_y < 0) with a normal within 25 deg of camera up, refitted
    by least squares on its inliers -> (n, d, inlier mask). Shape: p (M, 3)."""
    best = np.zeros(len(p), bool)
    for _ in range(tries):
        a, b, c = p[rng.choice(len(p), 3, replace=False)]
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) < 1e-9:
            continue
        n = n / np.linalg.norm(n) * (-1 if n[1] > 0 else 1)
        if -n[1] < np.cos(np.radians(25)):
            continue
        inl = np.abs(p @ n - n @ a) < INLIER_M
        if inl.sum() > best.sum():
            best = inl
    q = p[best]
    centre = q.mean(0)
    n = np.linalg.svd(q - centre, full_matrices=False)[2][2]
    n = n * (-1 if n[1] > 0 else 1)
    return n, float(-n @ centre), best


def road_evidence(depth: np.ndarray, K: np.ndarray, T: np.ndarray) -> dict:
    """The road candidate and the tilt candidate over one run. Shape: depth (N, H, W), T (N, 4, 4) estimated."""
    rng = np.random.default_rng(0)
    planes = []
    for d in depth:
        p = road_points(d, K)
        planes.append(None if len(p) < 30 else (*fit_plane(p, rng), p))
    corrected = [T[0]]
    for k in range(1, len(T)):
        rel = np.linalg.inv(T[k]) @ T[k - 1]                       # frame k-1 camera -> frame k camera
        C = np.eye(4)
        if planes[k] is not None and planes[k - 1] is not None:
            n0, _, inl0, p0 = planes[k - 1]
            q = p0[inl0] @ rel[:3, :3].T + rel[:3, 3]
            centre = q.mean(0)
            m = np.linalg.svd(q - centre, full_matrices=False)[2][2]
            m = m * (-1 if m[1] > 0 else 1)
            n1, d1 = planes[k][0], planes[k][1]
            C = align_planes(m, float(-m @ centre), n1, d1)
        corrected.append(corrected[-1] @ np.linalg.inv(C @ rel))
    corrected = np.stack(corrected)
    gap = corrected[-1, :3, 3] - T[-1, :3, 3]
    up0 = T[0, :3, :3] @ planes[0][0] if planes[0] is not None else None
    upN = T[-1, :3, :3] @ planes[-1][0] if planes[-1] is not None else None
    tilt = float(np.degrees(np.arccos(np.clip(up0 @ upN, -1, 1)))) if up0 is not None and upN is not None else None
    vertical = float(gap @ (T[0, :3, :3][:, 1]))
    return {"road_m": float(np.linalg.norm(gap)), "road_vertical_m": vertical, "tilt_deg": tilt,
            "road_frames": sum(p is not None for p in planes)}


def horizontal_bound(reports, up: np.ndarray) -> float:
    """The drift bound (dcslam.slam.health.drift_bound) maximised over the directions perpendicular to ``up`` (3,)
    world only: what is left of it when the road measures the vertical."""
    from dcslam.slam.health import HealthRules, _correlated_std, _drift, _position_covariances

    rules = HealthRules()
    _, curve = _drift(reports, rules)
    if curve is None:
        return 0.0
    _, A, X, B, at, positions = curve
    P = _position_covariances(A, X, B, positions[-1][None, :] - positions[at])
    e1 = np.linalg.svd(up[None])[2][1]
    e2 = np.cross(up, e1)
    angles = np.linspace(0, np.pi, 361)
    U = np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2
    return float(rules.drift_sigmas * _correlated_std(P, U).sum(0).max())


def slam_run(path: Path, kind: str, frames: int, local_map_frames: int | None = None):
    from dcslam.slam.config import build_slam
    from dcslam.stages.slam import SlamStageConfig, run_drive_file

    config = SlamStageConfig(depth=kind, frames=frames, evidence="none",
                             **({} if local_map_frames is None else {"local_map_frames": local_map_frames}))
    return run_drive_file(path, kind, build_slam(config.settings()), frames)


def measure(path: Path, kind: str, frames: int, s2s: bool) -> dict:
    """One run's row: its errors, its verdict as the rules are, and every candidate's figure."""
    from dcslam.io.drive import DriveFile, load_depth
    from dcslam.slam.health import HealthRules, summarise

    run = slam_run(path, kind, frames)
    summary = run.summary()
    T, G = run.T_world_cam, run.T_gt
    err = T[-1, :3, 3] - G[-1, :3, 3]
    with DriveFile(path) as drive:
        depth, K = load_depth(drive, kind)[:len(T)], np.asarray(drive.K, np.float64)
    row = {"drive": path.stem, "kind": kind, "final_m": summary["translation_error_m"]["final"],
           "vertical_m": float(err @ G[0, :3, :3][:, 1]), "flagged": bool(summary["health"]["suspect"]),
           "horizontal_m": float(np.linalg.norm(err - (err @ G[0, :3, :3][:, 1]) * G[0, :3, :3][:, 1])),
           "flagged_without_bound": bool(summarise(run.reports, HealthRules(max_drift_m=0))["suspect"]),
           "direction": summary["health"]["drift"]["direction"],
           "horizontal_bound_m": horizontal_bound(run.reports, -T[0, :3, :3][:, 1]),
           "bound_m": summary["health"]["drift"]["bound_m"],
           **road_evidence(depth, K, T)}
    if s2s:
        T2 = slam_run(path, kind, frames, local_map_frames=1).T_world_cam
        gap = T2[-1, :3, 3] - T[-1, :3, 3]
        row.update(s2s_m=float(np.linalg.norm(gap)), s2s_vertical_m=float(gap @ T[0, :3, :3][:, 1]))
    return row


FIGURES = ("road_m", "road_vertical_m", "tilt_deg", "s2s_m", "s2s_vertical_m")


def separation(rows: list[dict], figure: str, truth: float, first: set, horizontal: bool = False) -> list[str]:
    """The rule "the step rules (no drift bound) or |figure| > t" (and, with ``horizontal``, "or the drift bound
    over the horizontal directions exceeds ``truth``"), t one threshold for every input: the largest that flags
    every bad run of the first half of the seeds. Lines: the threshold, then per input its counts on both halves."""
    have = [r for r in rows if r.get(figure) is not None]
    if not have:
        return [f"{figure}: not measured"]

    def other(r):
        return r["flagged_without_bound"] or (horizontal and r["horizontal_bound_m"] > truth)

    need = [abs(r[figure]) for r in have if r["drive"] in first and r["final_m"] > truth and not other(r)]
    tau = min(need) - 1e-6 if need else None
    lines = [f"{figure}{' + horizontal bound' if horizontal else ''}: threshold "
             + (f"{tau:.3f}" if need else "none needed (the other rules flag every bad run of the first half)")]
    for kind in sorted({r["kind"] for r in have}):
        out = []
        for name, half in (("first", [r for r in have if r["kind"] == kind and r["drive"] in first]),
                           ("second", [r for r in have if r["kind"] == kind and r["drive"] not in first])):
            def flag(r):
                return other(r) or (tau is not None and abs(r[figure]) > tau)

            b = [r for r in half if r["final_m"] > truth]
            g = [r for r in half if r["final_m"] <= truth]
            out.append(f"{name}: bad flagged {sum(map(flag, b))}/{len(b)}, good {sum(map(flag, g))}/{len(g)}")
        lines.append(f"    {kind:9s} " + "; ".join(out))
    return lines


def main(argv=None) -> int:
    from benchmarks.slam_degeneracy import make_drives, seeds_of

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--seeds", default="7171-7186")
    parser.add_argument("--fit-seeds", default="7171-7178", help="seeds the thresholds are picked on")
    parser.add_argument("--beams", default="8,16")
    parser.add_argument("--kinds", default="sparse,exact", help="kinds run on the first beams' drives too")
    parser.add_argument("--frames", type=int, default=32)
    parser.add_argument("--slam-frames", type=int, default=30)
    parser.add_argument("--s2s", default="8", help="beam counts (or kinds) whose runs also get the s2s candidate")
    parser.add_argument("--truth", type=float, default=0.5)
    parser.add_argument("--rows", action="store_true", help="re-read <out>/road_rows.json")
    parser.add_argument("--resume", action="store_true", help="keep the runs of <out>/road_rows.json, run the rest")
    args = parser.parse_args(argv)
    first = {f"drive{s}" for s in seeds_of(args.fit_seeds)}
    rows_path = args.out / "road_rows.json"
    rows = json.loads(rows_path.read_text()) if args.rows or args.resume else []
    done = {(r["drive"], r["kind"]) for r in rows}
    if not args.rows:
        import torch

        torch.set_num_threads(1)
        s2s = set(args.s2s.split(","))
        for k, beams in enumerate(int(b) for b in args.beams.split(",")):
            drives = make_drives(args.out / f"beams{beams}", seeds_of(args.seeds), beams, args.frames)
            kinds = [f"sparse@{beams}"] + ([x for x in args.kinds.split(",") if x] if k == 0 else [])
            for kind in kinds:
                for path in (p for p in drives if (p.stem, kind) not in done):
                    row = measure(path, kind, args.slam_frames, str(beams) in s2s and kind.startswith("sparse@")
                                  or kind in s2s)
                    rows.append(row)
                    print(" ".join(f"{key}={v:.3f}" if isinstance(v, float) else f"{key}={v}"
                                   for key, v in row.items()), flush=True)
                    rows_path.write_text(json.dumps(rows, indent=1))
    for figure in FIGURES:
        for horizontal in (False, True):
            print("\n".join(separation(rows, figure, args.truth, first, horizontal)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
