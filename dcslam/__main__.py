"""`python -m dcslam`: the command line (dcslam.launch, then dcslam.cli)."""
from dcslam.launch import main

main()
