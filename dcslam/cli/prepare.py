"""`dcslam prepare-kitti`."""
from dcslam.cli.app import app, not_yet_built


@app.command("prepare-kitti", help="Not yet built (the data-layer issue).")
def prepare_command() -> None:
    not_yet_built("prepare-kitti", "the data-layer issue")
