"""One module per command: a configuration dataclass declared once + ``run(workspace, config, force=) -> result``.

``synth``, ``prepare`` (KITTI), ``prepare_tum``, ``train``, ``predict``, ``filter``, ``slam``, ``score``,
``demo_icl`` and ``reproduce``. A stage returns a value and never prints or exits; the command line (``dcslam.cli``)
turns options into its configuration (:mod:`dcslam.stages.config`) and prints a summary of its result. Each stage
writes the configuration it ran beside its outputs.
"""
