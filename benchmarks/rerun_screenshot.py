"""Screenshot of a ``dcslam slam --record`` recording in Rerun's own web viewer, rendered by headless Chromium with
its software WebGL2 (SwiftShader), so that it runs on a machine without a GPU or a display.

The recording and a blueprint (the layout: the 3D world with the map, trajectories and current frame; the camera
image; the input depth; the ICP pairs and sources per frame) are served over HTTP from a temporary folder; the web
viewer that ``rerun --serve-web`` hosts loads both (``?url=...``); Chromium is driven over the DevTools protocol on
a pipe (``--remote-debugging-pipe``, so nothing beyond the standard library is needed) and the page is captured once
two captures ``--settle`` seconds apart are the same (the data loaded, the images decoded, the last frame drawn).
The PNG is reduced to ``--colors`` colours so that it stays small in the repository.

    dcslam synth --drives 1 --frames 41 --seed 0 -w WS && dcslam prepare-kitti --all-drives -w WS
    dcslam predict --model ip-basic-fast -w WS
    dcslam slam --depth predicted --run ip-basic-fast --frames 30 --record -w WS
    python benchmarks/rerun_screenshot.py WS/slam/ip-basic-fast/2011_09_26_drive_1000_sync.rrd shot.png

made ``docs/img/rerun_recording.png`` (the defaults: 1400 x 800, the 3D eye and target below, 256 colours).

Needs ``rerun`` (rerun-sdk, the ``viz`` extra) on PATH or beside this Python, and ``chromium`` (or ``--chromium``).
"""
from __future__ import annotations

import argparse
import base64
import functools
import http.server
import io
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
from pathlib import Path

APPLICATION_ID = "dcslam"  # the recordings' application id (dcslam.slam.record): a blueprint applies to it
CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                  "--enable-webgl", "--ignore-gpu-blocklist", "--hide-scrollbars", "--mute-audio")
#: A capture with fewer colours is the viewer's empty frame, not a drawn recording (the loading page has a handful; the
#: recording drawn, tens of thousands).
MIN_COLOURS = 1000


def save_blueprint(path: Path, eye: list[float], target: list[float]) -> None:
    """The layout as a Rerun blueprint file: the 3D world seen from ``eye`` towards ``target`` (world metres; the
    world is the first camera's frame, x right, y down, z forward), beside the camera image, the input depth and the
    per-frame ICP pairs and sources; the side panels closed, the time cursor following the last frame."""
    import rerun.blueprint as rrb

    rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="/world", name="map, trajectories and the current frame",
                              eye_controls=rrb.EyeControls3D(position=eye, look_target=target, eye_up=[0, -1, 0])),
            rrb.Vertical(
                rrb.Spatial2DView(origin="/world/camera/image", contents="$origin/rgb", name="camera image"),
                rrb.Spatial2DView(origin="/world/camera/image", contents="$origin/depth", name="input depth"),
                rrb.TimeSeriesView(origin="/steps", contents=["$origin/pairs", "$origin/sources"],
                                   name="ICP pairs and sources per frame"),
                row_shares=[1, 1, 2.2]),
            column_shares=[2, 1]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline="frame", play_state="following"),
    ).save(APPLICATION_ID, str(path))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _CorsHandler(http.server.SimpleHTTPRequestHandler):
    """Serves a folder to the viewer, which runs on another port (another origin): CORS allowed, no log lines."""

    def end_headers(self) -> None:
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()

    def log_message(self, *args) -> None:
        pass


def serve_folder(folder: Path) -> tuple[http.server.ThreadingHTTPServer, int]:
    """An HTTP server of ``folder`` on a free local port, in a daemon thread."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_CorsHandler, directory=folder))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, server.server_address[1]


def rerun_executable() -> str:
    """``rerun`` beside this Python (a venv's bin/), else on PATH."""
    beside = Path(sys.executable).with_name("rerun")
    found = str(beside) if beside.is_file() else shutil.which("rerun")
    if not found:
        sys.exit("rerun not found (pip install 'dcslam[viz]')")
    return found


def start_viewer(port: int, log: Path) -> subprocess.Popen:
    """Rerun's web viewer hosted on ``port`` (its gRPC proxy on another free port, unused here)."""
    return subprocess.Popen([rerun_executable(), "--serve-web", "--web-viewer-port", str(port),
                             "--port", str(free_port())], stdout=log.open("w"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def wait_for_port(port: int, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError(f"nothing listens on port {port} after {seconds:.0f} s")


class Chromium:
    """Headless Chromium driven over the DevTools protocol on a pipe: JSON messages ended by NUL, written to its fd 3
    and read from its fd 4."""

    def __init__(self, executable: str, width: int, height: int, log: Path) -> None:
        to_child, self._to = os.pipe()
        self._from, from_child = os.pipe()

        def as_fds_3_and_4() -> None:  # runs in the child, before exec
            os.dup2(to_child, 100)  # both set aside first: either may itself be fd 3 or 4
            os.dup2(from_child, 101)
            os.dup2(100, 3)
            os.dup2(101, 4)

        self.proc = subprocess.Popen([executable, "--remote-debugging-pipe", *CHROMIUM_FLAGS,
                                      f"--window-size={width},{height}", "about:blank"],
                                     close_fds=False, preexec_fn=as_fds_3_and_4, stdout=log.open("w"),
                                     stderr=subprocess.STDOUT, start_new_session=True)
        os.close(to_child)
        os.close(from_child)
        self._buffer, self._id, self.session = b"", 0, None

    def send(self, method: str, **params) -> dict:
        """Send one command (to the attached page once there is one) and return its result."""
        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if self.session and not method.startswith(("Target.", "Browser.")):
            message["sessionId"] = self.session
        os.write(self._to, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def _read(self) -> dict:
        while b"\0" not in self._buffer:
            chunk = os.read(self._from, 1 << 20)
            if not chunk:
                raise EOFError(f"chromium exited (code {self.proc.poll()})")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def open(self, url: str, width: int, height: int) -> None:
        page = next(t for t in self.send("Target.getTargets")["targetInfos"] if t["type"] == "page")
        self.session = self.send("Target.attachToTarget", targetId=page["targetId"], flatten=True)["sessionId"]
        self.send("Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1,
                  mobile=False)
        self.send("Page.navigate", url=url)

    def capture(self) -> bytes:
        return base64.b64decode(self.send("Page.captureScreenshot", format="png")["data"])

    def close(self) -> None:
        try:
            self.send("Browser.close")
            self.proc.wait(10)
        except (EOFError, OSError, RuntimeError, subprocess.TimeoutExpired):
            os.killpg(self.proc.pid, 15)


def settled_capture(browser: Chromium, settle: float, limit: float) -> tuple[bytes, float]:
    """The first capture equal to the one ``settle`` seconds before it (the page no longer changes), and the seconds
    waited; after ``limit`` seconds, the last capture."""
    start, previous = time.monotonic(), None
    while True:
        time.sleep(settle)
        shot = browser.capture()
        waited = time.monotonic() - start
        if shot == previous or waited > limit:
            return shot, waited
        previous = shot


def reduce_colors(png: bytes, colors: int) -> bytes:
    """The PNG with at most ``colors`` colours (a palette PNG), optimised."""
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    out = io.BytesIO()
    image.quantize(colors=colors, method=Image.Quantize.FASTOCTREE).save(
        out, format="PNG", optimize=True)
    return out.getvalue()


def distinct_colours(png: bytes) -> int:
    from PIL import Image

    return len(Image.open(io.BytesIO(png)).convert("RGB").getcolors(maxcolors=1 << 24))


def screenshot(recording: Path, out: Path, args: argparse.Namespace) -> float:
    """Write ``out`` from ``recording``; the seconds the page took to settle. A page of fewer than
    :data:`MIN_COLOURS` colours (the viewer's empty frame: WebGL2 unavailable, or nothing loaded) is refused."""
    with tempfile.TemporaryDirectory(prefix="rerun-shot-") as tmp:
        tmp = Path(tmp)
        shutil.copyfile(recording, tmp / "recording.rrd")
        save_blueprint(tmp / "layout.rbl", args.eye, args.target)
        # Chromium first: its start runs code in the forked child, which is safe only while no thread runs yet
        browser = Chromium(args.chromium, args.width, args.height, tmp / "chromium.log")
        files = viewer = None
        try:
            files, files_port = serve_folder(tmp)
            viewer_port = free_port()
            viewer = start_viewer(viewer_port, tmp / "rerun.log")
            wait_for_port(viewer_port)
            urls = [f"http://127.0.0.1:{files_port}/{name}" for name in ("recording.rrd", "layout.rbl")]
            query = urllib.parse.urlencode([("url", u) for u in urls] + [("renderer", "webgl")])
            browser.open(f"http://127.0.0.1:{viewer_port}/?{query}", args.width, args.height)
            png, waited = settled_capture(browser, args.settle, args.limit)
        finally:
            browser.close()
            if viewer is not None:
                os.killpg(viewer.pid, 15)
                viewer.wait(10)
            if files is not None:
                files.shutdown()
    if distinct_colours(png) < MIN_COLOURS:
        sys.exit(f"the page has fewer than {MIN_COLOURS} colours: the viewer drew nothing (no WebGL2?); "
                 f"nothing written")
    out.write_bytes(reduce_colors(png, args.colors) if args.colors else png)
    return waited


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", type=Path, help="a .rrd written by `dcslam slam --record`")
    parser.add_argument("out", type=Path, help="the PNG to write")
    parser.add_argument("--width", type=int, default=1400)
    parser.add_argument("--height", type=int, default=800)
    parser.add_argument("--eye", type=float, nargs=3, default=[-20.0, -22.0, -14.0],
                        help="3D view eye, world metres (the first camera's frame: x right, y down, z forward)")
    parser.add_argument("--target", type=float, nargs=3, default=[0.0, 0.0, 26.0], help="3D view look target")
    parser.add_argument("--settle", type=float, default=10.0, help="seconds between captures compared")
    parser.add_argument("--limit", type=float, default=300.0, help="capture anyway after this many seconds")
    parser.add_argument("--colors", type=int, default=256, help="palette size of the PNG (0: keep full colour)")
    parser.add_argument("--chromium", default=shutil.which("chromium") or "chromium")
    args = parser.parse_args(argv)
    waited = screenshot(args.recording, args.out, args)
    print(f"{args.out}: {args.out.stat().st_size / 1024:.0f} KiB, captured after {waited:.0f} s")


if __name__ == "__main__":
    main()
