"""`python -m dcslam`: the command line (dcslam.cli)."""
import dcslam.cli

dcslam.cli.main()
