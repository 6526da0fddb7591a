"""`dcslam synth`."""
from dcslam.cli.app import app, not_yet_built


@app.command("synth", help="Not yet built (the data-layer issue).")
def synth_command() -> None:
    not_yet_built("synth", "the data-layer issue")
