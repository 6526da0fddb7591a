"""The SLAM's settings, declared once, and the one place where they become SLAM objects.

:class:`SlamSettings` holds every algorithm setting of a SLAM run (odometry, mapper, solver, association, gates,
iterations, voxel size). Each field carries its help text in ``metadata["help"]`` so that the command line and the
stage configuration take defaults and help from here instead of repeating them. :func:`build_slam` maps the names
to objects; nothing else in dcslam switches on these strings.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

from dcslam.constants import FIRST_STEP_PRIORS

ODOMETRIES = ("gt", "icp", "gradicp")
MAPPERS = ("pointfusion", "icpslam")
SOLVERS = ("gn", "lm")
ASSOCIATIONS = ("projective", "nn")
KERNELS = ("none", "gm")


@dataclass(frozen=True)
class SlamSettings:
    """Algorithm settings of one SLAM run (no paths, no devices)."""

    odometry: str = field(default="icp", metadata={
        "help": "gt: drive poses; icp: point-to-plane ICP; gradicp: ICP with the differentiable LM.",
        "choices": ODOMETRIES})
    mapper: str = field(default="pointfusion", metadata={
        "help": "pointfusion or icpslam.", "choices": MAPPERS})
    solver: str = field(default="gn", metadata={
        "help": "ICP solver: gn (Gauss-Newton) or lm.", "choices": SOLVERS})
    association: str = field(default="projective", metadata={
        "help": "ICP association: projective or nn (KD-tree).", "choices": ASSOCIATIONS})
    max_distance: float = field(default=0.5, metadata={"help": "ICP outlier gate, metres.", "min": 0.0})
    max_normal_angle: float = field(default=30.0, metadata={"help": "ICP normal-angle gate, degrees.", "min": 0.0})
    iterations: int = field(default=20, metadata={"help": "ICP iterations per gate stage.", "min": 1})
    coarse_iterations: int = field(default=0, metadata={
        "help": "ICP iterations of each wide-gate stage (all but the last of --gate-schedule); 0 = from the depth's "
                "density: 3 for depth with a value at more than 30 % of the pixels (completed, exact), where wide "
                "gates only oscillate, --iterations for sparser depth (LiDAR, annotated).", "min": 0})
    voxel_size: float = field(default=0.2, metadata={
        "help": "Map voxel size, metres (for a street; see reference_depth).", "min": 0.0})
    kernel: str = field(default="none", metadata={
        "help": "ICP robust kernel: none (hard gates only) or gm (Geman-McClure, scale gate/9 as KISS-ICP).",
        "choices": KERNELS})
    adaptive_threshold: bool = field(default=False, metadata={
        "help": "KISS-ICP's adaptive gate (3 sigma of past prediction errors) instead of --max-distance."})
    source_voxel: float = field(default=0.2, metadata={
        "help": "Odometry aligns one frame point per voxel of this size, metres (0 = every point).", "min": 0.0})
    gate_schedule: str = field(default="4,2,1", metadata={
        "help": "Gate multipliers, one solver run each, wide to narrow (e.g. 4,2,1; 1 = a single gate)."})
    tolerance: float = field(default=1e-4, metadata={
        "help": "Solver stops when a step moves less than this (metres / radians).", "min": 0.0})
    hold_below: float = field(default=2.5e-3, metadata={
        "help": "Keep the constant-velocity prediction along directions the scene does not constrain (normalised "
                "eigenvalue below this; 0 = never).", "min": 0.0})
    reference_depth: float = field(default=12.0, metadata={
        "help": "Voxel sizes and the ICP gate are for scenes of this median depth, metres (streets); a sequence "
                "whose first frame is nearer (a room) scales them down in proportion (0 = never).", "min": 0.0})
    local_map_frames: int = field(default=50, metadata={
        "help": "Odometry and fusion use the points seen in the last N frames (0 = the whole map); older points "
                "are archived for the map file, so time and memory per frame stay flat.", "min": 0})
    keep_global_map: bool = field(default=True, metadata={
        "help": "Keep the points that leave the local map (in a temporary file, read back when the map is written) "
                "so the whole map can be written; off: they are dropped."})
    first_step_prior: str = field(default="none", metadata={
        "help": "Motion prediction of the first ICP step, which has no velocity to predict from: none (no motion: a "
                "car at 1 m per frame starts 1 m off) or drive-motion (the drive poses' motion from frame 0 to 1). "
                "drive-motion uses the drive's poses (OXTS on KITTI), data beyond the depth: a run with it is not "
                "depth-only odometry.", "choices": FIRST_STEP_PRIORS})
    normal_search: int = field(default=0, metadata={
        "help": "Pixels searched along rows and columns for normal neighbours; 0 = from the depth's density.",
        "min": 0})

    def __post_init__(self) -> None:
        from dcslam.errors import DcslamError

        for name, choices in (("odometry", ODOMETRIES), ("mapper", MAPPERS), ("solver", SOLVERS),
                              ("association", ASSOCIATIONS), ("kernel", KERNELS),
                              ("first_step_prior", FIRST_STEP_PRIORS)):
            if getattr(self, name) not in choices:
                raise DcslamError(f"unknown {name} {getattr(self, name)!r} (choose from {', '.join(choices)})")
        for name in ("max_distance", "max_normal_angle", "voxel_size", "source_voxel", "reference_depth",
                     "hold_below"):
            if not getattr(self, name) >= 0:
                raise DcslamError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.iterations < 1:
            raise DcslamError(f"iterations must be >= 1, got {self.iterations}")
        if self.coarse_iterations < 0:
            raise DcslamError(f"coarse_iterations must be >= 0, got {self.coarse_iterations}")
        try:
            stages = tuple(float(x) for x in self.gate_schedule.split(","))
        except ValueError:
            stages = ()
        if not stages or any(not m > 0 for m in stages):
            raise DcslamError(f"gate_schedule must be positive numbers separated by commas, got {self.gate_schedule!r}")
        if self.local_map_frames < 0:
            raise DcslamError(f"local_map_frames must be >= 0, got {self.local_map_frames}")
        if self.normal_search < 0:
            raise DcslamError(f"normal_search must be >= 0, got {self.normal_search}")

    def to_dict(self) -> dict:
        return asdict(self)


def build_slam(settings: SlamSettings = SlamSettings()):
    """The one place where setting names become SLAM objects -> :class:`~dcslam.slam.pipeline.SLAM`."""
    from dcslam.slam.association import NearestNeighbourAssociation, ProjectiveAssociation
    from dcslam.slam.frame import FrameSettings
    from dcslam.slam.fusion import PointFusion
    from dcslam.slam.icpslam import ICPSLAM
    from dcslam.slam.odometry import GroundTruthOdometry, ICPOdometry
    from dcslam.slam.pipeline import SLAM
    from dcslam.slam.robust import AdaptiveThreshold, GemanMcClure
    from dcslam.slam.solvers import DifferentiableLM, GaussNewton, LevenbergMarquardt

    s = settings
    assoc = {"projective": ProjectiveAssociation, "nn": NearestNeighbourAssociation}[s.association]()
    if s.odometry == "gt":
        odo = GroundTruthOdometry()
    else:
        solver = DifferentiableLM(tolerance=s.tolerance) if s.odometry == "gradicp" else {
            "gn": GaussNewton, "lm": LevenbergMarquardt}[s.solver](tolerance=s.tolerance)
        odo = ICPOdometry(solver=solver, association=assoc, max_distance=s.max_distance,
                          max_normal_angle_deg=s.max_normal_angle, iterations=s.iterations,
                          kernel=GemanMcClure() if s.kernel == "gm" else None,
                          adaptive=AdaptiveThreshold() if s.adaptive_threshold else None,
                          source_voxel=s.source_voxel, hold_below=s.hold_below, coarse_iterations=s.coarse_iterations,
                          coarse_to_fine=tuple(float(x) for x in s.gate_schedule.split(",")))
    mapper = (PointFusion if s.mapper == "pointfusion" else ICPSLAM)(voxel_size=s.voxel_size,
                                                                      window=s.local_map_frames,
                                                                      archive=s.keep_global_map)
    return SLAM(odo, mapper, FrameSettings(normal_search=s.normal_search), reference_depth_m=s.reference_depth,
                first_step_prior=s.first_step_prior)
