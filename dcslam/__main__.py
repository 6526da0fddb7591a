from dcslam.cli import main

main()
