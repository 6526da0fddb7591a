"""`dcslam slam`: dense SLAM over drive files, writing a TUM trajectory, a PLY map and a JSON summary per drive
(options: dcslam.stages.slam, which takes the SLAM's own from dcslam.slam.config.SlamSettings)."""
from __future__ import annotations

from dcslam.cli.app import app, summary
from dcslam.cli.options import stage_command
from dcslam.slam.evidence import evidence_line
from dcslam.stages import slam

HELP = ("Dense SLAM over drive files (all test drives by default): writes per drive a TUM trajectory, a PLY map "
        "and a JSON summary under slam/<layer>/.")


def report(results: list[slam.SlamDriveResult]) -> None:
    for r in results:
        s, h = r.summary, r.summary["health"]
        verdict = f"SUSPECT ({'; '.join(h['reasons'])})" if h["suspect"] else "ok"
        used = s.get("sources", {})
        sources = f", ICP sources {used['kind']}" if used.get("mode") == "measured" else ""
        said = evidence_line(h)
        camera = h.get("camera") or {}
        if not h["suspect"] and camera.get("verdict") == "agrees":
            overruled = f"; overruled: {'; '.join(h['overruled'])}" if h.get("overruled") else ""
            verdict = f"ok, ends within {camera['gap_m']:.2f} m of the camera's trajectory{overruled}"
        elif not h["suspect"] and said:  # completed depth no companion vouches for is not simply ok
            verdict = f"ok, {said}" if h["evidence"]["verdict"] in ("agrees", "own") else f"UNVERIFIED ({said})"
        if camera.get("verdict") == "unmeasured":  # asked for and silent: say so, or it reads as if it agreed
            why = camera.get("note") or f"{camera['steps_measured']} of {camera['steps']} steps measured from images"
            verdict += f"; the camera abstained: {why}"
        summary(f"{r.drive}: {s['frames']} frames, {s['points']} points, {s['seconds_per_frame']:.2f} s/frame, "
                f"final drift {s['translation_error_m']['final']:.3f} m{sources}, steps {h['accepted']} accepted / "
                f"{h['degraded']} degraded / {h['rejected']} rejected, {verdict} -> {r.written['trajectory'].parent}")


slam_command = stage_command(app, "slam", slam.SlamStageConfig, slam.run, report, help=HELP,
                             examples=("dcslam slam --depth dense --odometry icp --frames 30",
                                       "dcslam slam --depth predicted --run mse-dense --mapper pointfusion"))
