"""`dcslam slam`."""
from dcslam.cli.app import app, not_yet_built


@app.command("slam", help="Not yet built (the SLAM issue).")
def slam_command() -> None:
    not_yet_built("slam", "the SLAM issue")
