"""The version of dcslam (one place: the package, the stamps and the provenance records read it)."""
__version__ = "0.1.0"
