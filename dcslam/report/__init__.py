"""Workspace-aware scoring: layers and trajectories of a workspace (``layers``), the per-layer and whole-report tables
(``scores``: Tables 5.1 and 5.2 with ``tables``), plots, and the denoising experiment's scores (``denoising``)."""
