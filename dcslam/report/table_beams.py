"""The beams experiment's table: depth and localisation of every input at every LiDAR beam count.

For each beam count B and each input made from the B-beam sparse depth — the sparse depth itself, IP-Basic's
completion, SparseConvNet (trained against the annotated depth, against the exact depth, and against the exact
depth with the geometry losses), nconv unmasked and masked by its confidence, nconv-guided, nconv fine-tuned through
the pose loss (its confidence as ICP weights), each completion again with measured ICP sources (the B-beam pixels
aligned against the map fused from it) and exact depth with those sources (the ceiling) — and for the inputs that do
not depend on B (annotated dense depth, the generator's exact depth): MAE / RMSE against the annotated depth and
localisation (the thesis's metric, ATE, RPE) as the mean over the test drives ± the half-width of the 95 % t-interval
(:mod:`dcslam.report.spread`), the median, the failures, whether the row differs from the sparse input of its beam
count beyond the spread (paired by drive), and the share of the gap from that sparse input to exact depth that it
closes; beside them the comparison with that sparse input that one failing drive does not swamp (signed-rank test,
bootstrap interval of the median paired difference, gap closed between medians; :mod:`dcslam.report.robust_rows`),
without the drives on which every row fails, which the notes name. A fine-tuned input is also compared with the
input it was fine-tuned from. Rows made with different SLAM settings are refused: a comparison across them would
mean nothing. The surface experiment's table is the same table over its own inputs (:data:`SURFACE_INPUTS`).

Layer names (one function, :func:`layer_name`, used by the pipeline that makes them and by this table):
``sparse`` / ``sparse@B`` (the drive files' depth), ``ip-basic-fast-sparseB``, ``<run>-sparseB`` (a trained
completer's predictions of the B-beam input), ``nconv-sparseB+masked`` (those predictions filtered by confidence),
``nconv-pose-sparseB`` (the pose-loss run's), ``dense``, ``exact``; the SLAM runs of a layer under ``slam/<layer>/``,
with measured sources under ``slam/<layer>+measured/`` (exact's ``slam/exact+measured-sparseB/``, :func:`slam_name`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dcslam.errors import DcslamError
from dcslam.eval.trajectory import EVO_MAX_TIME_DIFF_S
from dcslam.report.seeds import paired
from dcslam.report.spread import TWO_LEVEL_METHOD
from dcslam.report.results import (FAILURE_THRESHOLD, LayerResult, SeedResults, csv_suffixes, score_layer, seed_layer,
                                   seeded, surface_note, with_seed_columns)
from dcslam.report.robust_rows import ROBUST_NOTE, drive_localisation, left_out_text, robust_columns
from dcslam.report.tables import Column, Table
from dcslam.workspace import Workspace

FULL_BEAMS = 64  # the HDL-64E's lasers: the drive's own sparse depth
IP_BASIC_RUN = "ip-basic-fast"
MASKED = "masked"  # name of the confidence filter's output (``<run>-sparseB+masked``)


@dataclass(frozen=True)
class BeamsInput:
    """One input of the table: its label, the completer behind it (``None``: the sparse depth itself; ``""``: none,
    a layer of the drive files), whether it is masked by confidence, the label of the input it was fine-tuned from
    (``tuned_from``; its findings line compares the two), the ICP sources of its SLAM runs (``sources``:
    :data:`dcslam.stages.slam.SOURCES`; ``measured``: the B-beam sparse depth's pixels against the map fused from the
    layer) and whether it needs the generator's exact depth (``needs_exact``: the exact layer, or a completer
    trained against it)."""

    label: str
    completer: str | None
    masked: bool = False
    tuned_from: str | None = None
    sources: str = "depth"
    needs_exact: bool = False

    @property
    def per_beam(self) -> bool:
        """A row per beam count: a layer made from the B-beam input, or SLAM whose sources are the B-beam pixels."""
        return self.completer != "" or self.sources == MEASURED


MEASURED = "measured"
MEASURED_LABEL = ", measured sources"  # the label suffix of a measured-source row
_DEPTH_INPUTS = (BeamsInput("sparse", None), BeamsInput("IP-Basic", IP_BASIC_RUN),
                 BeamsInput("SparseConvNet", "sparse-conv"),
                 BeamsInput("SparseConvNet → exact", "sparse-conv-exact", needs_exact=True),
                 BeamsInput("SparseConvNet geometry", "sparse-conv-geometry", needs_exact=True),
                 BeamsInput("nconv", "nconv"), BeamsInput("nconv masked", "nconv", masked=True),
                 BeamsInput("nconv-guided", "nconv-guided"), BeamsInput("nconv pose", "nconv-pose", tuned_from="nconv"))
# measured sources for every completer but the masked one (its map is nconv's, less the pixels it drops) and for
# exact, the ceiling; the sparse input's measured sources are its own points, the same run as its depth row
_MEASURED_INPUTS = tuple(
    BeamsInput(i.label + MEASURED_LABEL, i.completer, tuned_from=i.tuned_from and i.tuned_from + MEASURED_LABEL,
               sources=MEASURED, needs_exact=i.needs_exact)
    for i in _DEPTH_INPUTS if i.completer is not None and not i.masked)
INPUTS = (*_DEPTH_INPUTS, *_MEASURED_INPUTS, BeamsInput("exact" + MEASURED_LABEL, "", sources=MEASURED,
                                                        needs_exact=True),
          BeamsInput("annotated dense", ""), BeamsInput("exact", "", needs_exact=True))
TRAINED = tuple(dict.fromkeys(i.completer for i in INPUTS if i.completer not in (None, "", IP_BASIC_RUN)))
"""Run names of the learned completers the table expects (``runs/<name>/``)."""
SURFACE_COMPLETERS = ("scanline", "planefit")  # the classical completers that keep planes and scanline structure
CLASSICAL_RUNS = (IP_BASIC_RUN, *SURFACE_COMPLETERS)
"""Completers of ``dcslam predict --model`` (no training) behind a row."""
SCAFFOLD_RUN, CONFIDENT_RUN = "sparse-conv-planefit", "sparse-conv-planefit-sure"
"""The surface experiment's learned completers: SparseConvNet correcting planefit's scaffold in inverse depth
(:mod:`dcslam.depth.models.scaffold`), trained against exact depth with the geometry losses; and the same with a
learned confidence (``confidence_weight``), whose predictions leave empty what it is not sure of."""
_SURFACE_DEPTH = (BeamsInput("sparse", None), BeamsInput("IP-Basic", IP_BASIC_RUN),
                  *(BeamsInput(c, c) for c in SURFACE_COMPLETERS),
                  BeamsInput("SparseConvNet on planefit", SCAFFOLD_RUN, needs_exact=True),
                  BeamsInput("SparseConvNet on planefit, sure", CONFIDENT_RUN, needs_exact=True))
SURFACE_INPUTS = (*_SURFACE_DEPTH, *(BeamsInput(i.label + MEASURED_LABEL, i.completer, sources=MEASURED,
                                                needs_exact=i.needs_exact)
                                     for i in _SURFACE_DEPTH if i.completer is not None),
                  BeamsInput("exact" + MEASURED_LABEL, "", sources=MEASURED, needs_exact=True),
                  BeamsInput("exact", "", needs_exact=True))
"""The rows of the surface experiment: the classical completers and the networks on planefit's scaffold, each in depth
mode and with measured sources, between the sparse input and exact depth (:mod:`dcslam.stages.experiments.surface`)."""
SURFACE_TRAINED = (SCAFFOLD_RUN, CONFIDENT_RUN)
LEARNED = (*TRAINED, *SURFACE_TRAINED)
"""Run names of every learned completer a table may hold, whose rows gather the runs of several training seeds."""
INPUT_OF = {i.label: i for i in (*INPUTS, *SURFACE_INPUTS)}  # a label names one input in every catalogue


def sparse_kind(beams: int) -> str:
    """The drive files' depth kind of ``beams`` beams: ``sparse`` for 64, ``sparse@B`` otherwise."""
    return "sparse" if beams == FULL_BEAMS else f"sparse@{beams}"


def prediction_name(completer: str, beams: int) -> str:
    """The prediction layer of ``completer`` (a run or IP-Basic) on the ``beams``-beam input."""
    return f"{completer}-sparse{beams}"


def layer_name(item: BeamsInput, beams: int | None, run: str | None = None) -> str:
    """The depth layer behind ``item`` at ``beams`` beams (``beams`` is ignored for the beam-independent layers);
    ``run``: the trained completer's run when it is not ``item.completer`` itself (another training seed's,
    :func:`dcslam.report.seeds.seed_run_name`)."""
    if item.completer == "":
        return "dense" if item.label == "annotated dense" else "exact"
    if item.completer is None:
        return sparse_kind(beams)
    name = prediction_name(run or item.completer, beams)
    return f"{name}+{MASKED}" if item.masked else name


def slam_name(item: BeamsInput, beams: int | None, run: str | None = None) -> str:
    """The folder of ``item``'s SLAM runs under ``slam/``: its layer's name in depth mode; with measured sources
    ``<layer>+measured`` (exact: ``exact+measured-sparseB``, one per beam count), apart from the depth-mode runs of
    the same layer."""
    layer = layer_name(item, beams, run)
    if item.sources != MEASURED:
        return layer
    return f"{layer}+{MEASURED}-sparse{beams}" if item.completer == "" else f"{layer}+{MEASURED}"


def seed_runs(ws: Workspace, completer: str) -> list[tuple[str, int | None]]:
    """The runs of ``completer`` trained with different seeds (``runs/<completer>``, ``runs/<completer>-s<k>``, by
    k; :func:`dcslam.report.seeds.seed_run_name`) with each one's training seed from its ``config.json``; just
    ``completer`` (seed unknown) when there are fewer than two such runs."""
    import json

    from dcslam.report.seeds import seed_base

    found = []
    if ws.runs.is_dir():
        for folder in ws.runs.iterdir():
            base, k = seed_base(folder.name)
            if base == completer and (folder / "config.json").is_file():
                try:
                    seed = json.loads((folder / "config.json").read_text()).get("settings", {}).get("seed")
                except json.JSONDecodeError:
                    raise DcslamError(f"{folder / 'config.json'}: not valid JSON") from None
                found.append((k, folder.name, seed))
    if len(found) < 2:
        seed = found[0][2] if found and found[0][1] == completer else None
        return [(completer, seed)]
    return [(name, seed) for _, name, seed in sorted(found)]


def beams_results(ws: Workspace, beams: list[int], drives: list[str], max_time_diff: float = EVO_MAX_TIME_DIFF_S,
                  failure_threshold: float = FAILURE_THRESHOLD,
                  jobs: int = 1, inputs: list[str] | None = None, catalogue: tuple = INPUTS) -> dict:
    """Scores of every (beam count, input): ``{(beams, label): result}``, beam counts from the largest; the
    beam-independent inputs last, under ``(None, label)``. A trained completer with runs of several seeds
    (:func:`seed_runs`) gives a :class:`dcslam.report.results.SeedResults` over them, other inputs a
    :class:`LayerResult`: the depth errors of the input's layer, the localisation of its SLAM runs
    (:func:`slam_name`). Missing inputs are recorded in each result (see
    :func:`dcslam.report.results.score_layer`); the inputs that need exact depth (:attr:`BeamsInput.needs_exact`)
    are left out when a test drive has none (real KITTI). ``jobs`` > 1 scores the layers in that many worker
    processes. ``inputs``: the labels of the rows to score (None: every input), e.g. a study of a few of them;
    ``catalogue``: the experiment's inputs (:data:`INPUTS`, :data:`SURFACE_INPUTS`)."""
    from dcslam.report.layers import surface_target

    check_inputs(inputs, catalogue)
    exact = surface_target(ws, drives) == "exact"
    inputs = [i for i in catalogue if (exact or not i.needs_exact) and (inputs is None or i.label in inputs)]
    keys = [(b, i) for b in sorted(beams, reverse=True) for i in inputs if i.per_beam]
    keys += [(None, i) for i in inputs if not i.per_beam]
    runs = {c: seed_runs(ws, c) for c in LEARNED}
    members = {key: runs[key[1].completer] if key[1].completer in LEARNED else [(None, None)] for key in keys}
    work = [(ws, item.label, layer_name(item, b, run), drives, max_time_diff, failure_threshold,
             slam_name(item, b, run))
            for b, item in keys for run, _ in members[(b, item)]]
    if jobs <= 1:
        scored = [_score(*args) for args in work]
    else:
        from dcslam.workers import process_pool

        with process_pool(jobs, len(work)) as pool:
            scored = list(pool.map(_score, *zip(*work)))
    results, at = {}, 0
    for b, item in keys:
        group = scored[at:at + len(members[(b, item)])]
        at += len(group)
        for result, (_, seed) in zip(group, members[(b, item)]):
            result.seed = seed
        results[(b, item.label)] = group[0] if len(group) == 1 else SeedResults(item.label, group)
    return results


def check_inputs(inputs: list[str] | None, catalogue: tuple = INPUTS) -> None:
    """A :class:`DcslamError` naming the first of ``inputs`` that is not a row label of the table (None: every row)."""
    labels = [i.label for i in catalogue]
    for label in inputs or ():
        if label not in labels:
            raise DcslamError(f"the beams table has no input {label!r}; choose from: {'; '.join(labels)}")
    if inputs is not None and not inputs:
        raise DcslamError("the beams table needs at least one input")


def _score(ws, label, layer, drives, max_time_diff, failure_threshold, slam) -> LayerResult:
    result = score_layer(ws, label, layer, drives, max_time_diff=max_time_diff, failure_threshold=failure_threshold,
                         slam_name=slam)
    _ = result.scores  # computed here, in the worker
    return result


CONFIDENCE_SETTINGS = ("confidence", "min_confidence")
MODE_SETTINGS = ("sources", "measured")  # checked per row against its input's mode (:func:`_check_mode`)


def common_settings(results: dict[tuple[int | None, str], LayerResult]) -> dict:
    """The SLAM settings every row was made with; a :class:`DcslamError` naming two rows that differ (and how), or
    a row whose ICP sources are not those of its input (:attr:`BeamsInput.sources`; a measured-source row's
    measured kind must be the sparse depth of its beam count, which differs from row to row as ``beams`` does).

    How a confidence was used (``confidence``, ``min_confidence``) is compared only among the rows whose layer has a
    confidence (mode other than ``none``): a layer without one (sparse, IP-Basic, SparseConvNet) cannot differ in it."""
    firsts: dict[str, tuple] = {}  # "base" / "confidence" → (settings, key) of the first row of that kind
    modes = set()
    for key, result in results.items():
        if not result.pairs:
            continue
        settings = {k: v for k, v in result.run_settings().items() if k != "beams"}
        modes.add(_check_mode(key, result, settings))
        parts = {"base": {k: v for k, v in settings.items() if k not in (*CONFIDENCE_SETTINGS, *MODE_SETTINGS)}}
        if settings.get("confidence", "none") not in (None, "none"):
            parts["confidence"] = {k: settings.get(k) for k in CONFIDENCE_SETTINGS}
        for part, own in parts.items():
            if part not in firsts:
                firsts[part] = (own, key)
                continue
            first, first_key = firsts[part]
            for name in sorted(set(first) | set(own)):
                if first.get(name) != own.get(name):
                    raise DcslamError(
                        f"the beams table mixes SLAM runs made with different settings: {name}={first.get(name)} "
                        f"for {_row_name(first_key)} ({results[first_key].layer}) but {name}={own.get(name)} for "
                        f"{_row_name(key)} ({result.layer}); rerun `dcslam reproduce --table beams` (or `dcslam "
                        "slam --force` on the odd layer) so that every row is made the same way")
    common = dict(firsts["base"][0]) if "base" in firsts else {}
    if "confidence" in firsts:
        common.update({f"{k} (layers with a confidence)": v for k, v in firsts["confidence"][0].items()})
    if modes:
        common["sources"] = " / ".join(m for m in ("depth", MEASURED) if m in modes)
    return common


def _check_mode(key: tuple[int | None, str], result: LayerResult, settings: dict) -> str:
    """The ICP sources of a row's SLAM runs (``depth`` for a summary that records none), refused unless they are
    those of its input and, measured, the sparse depth of its beam count."""
    item = INPUT_OF.get(key[1])
    want = item.sources if item is not None else "depth"
    ran = settings.get("sources") or "depth"
    if ran != want:
        raise DcslamError(
            f"the beams table's row {_row_name(key)} ({result.layer}) was made with sources={ran}, its rows with "
            f"sources={want}; rerun `dcslam reproduce --table beams` (or `dcslam slam --sources {want} --force` on "
            "that row's layer)")
    kind = settings.get("measured")
    if want == MEASURED and key[0] is not None and kind is not None and kind != sparse_kind(key[0]):
        raise DcslamError(
            f"the beams table's row {_row_name(key)} ({result.layer}) aligned measured={kind}, not the "
            f"{key[0]}-beam sparse depth ({sparse_kind(key[0])}); rerun `dcslam reproduce --table beams` (or "
            f"`dcslam slam --sources measured --measured {sparse_kind(key[0])} --force` on that row's layer)")
    return ran


def _row_name(key: tuple[int | None, str]) -> str:
    beams, label = key
    return label if beams is None else f"{label} at {beams} beams"


GAP_NOTE = ("gap closed: (sparse − row) / (sparse − exact) of the mean localisation at that beam count (100 % = as "
            "good as exact depth, < 0 = worse than sparse)")
COLUMNS = [Column("beams", "beams"), Column("input", "input"), Column("layer", "layer"), Column("drives", "drives"),
           Column("failures", "failed"), Column("localisation_text", "localisation"),
           Column("localisation_median_text", "median"), Column("vs_sparse", "vs sparse"),
           Column("gap_closed_text", "gap closed"), Column("signed_rank_p_text", "signed-rank p"),
           Column("median_diff_text", "median Δ vs sparse"), Column("robust_vs_sparse", "robust vs sparse"),
           Column("gap_closed_median_text", "gap closed (medians)"), Column("mae_mm_text", "MAE (mm)"),
           Column("rmse_mm_text", "RMSE (mm)"), Column("ate_rmse_m_text", "ATE RMSE (m)"),
           Column("rpe_rmse_m_text", "RPE RMSE (m)"), Column("rpe_rmse_deg_text", "RPE RMSE (°)"),
           Column("notes", "why —")]
FIGURES = ("localisation", "mae_mm", "rmse_mm", "ate_rmse_m", "rpe_rmse_m", "rpe_rmse_deg", "normal_mean_deg",
           "normal_median_deg", "p2p_mean_m", "p2p_rmse_m", "flying_share")


def _verdict(result, reference) -> str | None:
    if reference is None or not reference.pairs or not result.pairs:
        return None
    if result is reference:
        return "reference"
    verdict, difference = paired(result, reference)
    if verdict is None:
        return "one drive"
    if not verdict:
        return "within spread"
    return "better" if difference < 0 else "worse"


def _gap_closed(result: LayerResult, sparse: LayerResult | None, exact: LayerResult | None) -> float | None:
    if result.localisation is None or sparse is None or exact is None or None in (sparse.localisation,
                                                                                  exact.localisation):
        return None
    gap = sparse.localisation - exact.localisation
    return None if gap <= 0 else (sparse.localisation - result.localisation) / gap


ROBUST_CSV = ("robust_drives", "signed_rank_n", "signed_rank_p", "median_diff", "median_diff_ci_low",
              "median_diff_ci_high", "robust_vs_sparse", "gap_closed_median")


def csv_columns(seeds: bool) -> list[Column]:
    """The beams table's CSV columns: every figure's mean, spread and median (with ``seeds``: its seed-to-seed std)."""
    return [Column(k, k) for k in ("beams", "input", "layer", "sources", "drives", *(("seeds",) if seeds else ()),
                                   "failures", "vs_sparse", "gap_closed", *ROBUST_CSV)] + [
        Column(f"{k}{s}", "") for k in FIGURES for s in csv_suffixes(seeds)] + [Column("missing", "")]


def table_beams(results: dict[tuple[int | None, str], LayerResult], beams: list[int], drives: list[str],
                name: str = "beams", catalogue: tuple = INPUTS) -> Table:
    """The beams table (of experiment ``name``, its inputs ``catalogue``): one row per (beam count, input), then the
    beam-independent rows (compared with the 64-beam sparse input, or the largest beam count's). Refuses rows made
    with different SLAM settings."""
    settings = common_settings(results)
    frames = {p.T_est.shape[0] for r in results.values() for p in r.pairs.values()}
    seeds = seeded(list(results.values()))
    table = Table(f"The {name} experiment — {len(drives)} test drive(s) ({', '.join(drives)})",
                  with_seed_columns(COLUMNS, seeds))
    table.csv_columns = csv_columns(seeds)
    exact = results.get((None, "exact"))
    top = max(beams)
    robust, failed_all = robust_columns(results, beams)
    for key, result in results.items():
        b, label = key
        sparse = results.get((b if b is not None else top, "sparse"))
        row = result.row()
        item = INPUT_OF.get(label)
        row.update(beams=b if b is not None else "any", input=label, vs_sparse=_verdict(result, sparse),
                   sources=item.sources if item is not None else "depth")
        gap = None if result is exact else _gap_closed(result, sparse, exact)
        row["gap_closed"] = gap
        row["gap_closed_text"] = None if gap is None else f"{100 * gap:.0f} %"
        row.update(robust.get(key, {}))
        row["notes"] = row.get("missing")
        table.rows.append(row)
    table.notes += [
        f"{len(drives)} test drives × {'/'.join(map(str, sorted(frames))) or '—'} SLAM frames each; every figure: "
        "mean over the test drives ± the half-width of its 95 % t-interval (std, interval and median in the CSV, "
        "every drive in the per-drive CSV)",
        "localisation: the thesis's metric, mean over poses of ‖t_X‖ + acos((tr R_X − 1)/2), X = T_gt⁻¹ T_est "
        "(m + rad); lower is better",
        f"vs sparse: paired t-interval (95 %) of the per-drive differences from the sparse input of the same beam "
        f"count (rows 'any': from {top}-beam sparse); better / worse beyond the spread, or within it",
        GAP_NOTE,
        ROBUST_NOTE if robust else "",
        left_out_text(failed_all) if robust else "",
        measured_note(results),
        left_out_note(results, catalogue),
        "MAE / RMSE: against the annotated depth, KITTI devkit with dcslam's two departures (predictions below 0.1 m "
        "are holes; pixels the devkit cannot interpolate are left out)",
        surface_note(list(results.values())),
        f"which depth metric predicts localisation: table_{name}_correlation.md",
        f"failed: drives whose SLAM run was flagged suspect (rejected or degraded steps, drift bound, a departure from "
        f"the companion run on the measured pixels or a companion itself suspect) or whose "
        f"localisation exceeds "
        f"{next(iter(results.values())).failure_threshold:g} m + rad (kept in the means)" if results else "",
        "SLAM settings of every row: " + (", ".join(f"{k}={settings[k]}" for k in sorted(settings)) or "none "
                                           "recorded"),
        (f"rows over several training seeds (seeds: their number; layer: the first seed's): every figure is the "
         f"mean over seeds × test drives with its 95 % interval [low, high] from a {TWO_LEVEL_METHOD}; "
         "seed-to-seed std: the std of the per-seed mean localisations; failed: failed runs of all seeds × drives; "
         "vs sparse (and the findings' comparisons): the same two-level interval of the per-run differences "
         "(paired by drive, and by seed between two rows over seeds)" if seeds else ""),
        *findings(results, beams)]
    table.notes = [n for n in table.notes if n]
    return table


def measured_note(results: dict[tuple[int | None, str], LayerResult]) -> str:
    """The note on the measured-source rows; empty when the table has none."""
    if not any(INPUT_OF.get(k[1]) is not None and INPUT_OF[k[1]].sources == MEASURED for k in results):
        return ""
    return ("measured sources: SLAM whose ICP aligns only the B-beam sparse depth's measured pixels against the map "
            "fused from the row's layer (`dcslam slam --sources measured`; runs under slam/<layer>+measured/, "
            "exact's under slam/exact+measured-sparseB/); its depth figures are the layer's, as in its depth-mode row")


def left_out_note(results: dict[tuple[int | None, str], LayerResult], catalogue: tuple = INPUTS) -> str:
    """One line naming the inputs that need exact depth when the results hold none of them (drives without it,
    real KITTI); empty otherwise."""
    absent = [i.label for i in catalogue if i.needs_exact and not any(k[1] == i.label for k in results)]
    if not results or len(absent) < sum(i.needs_exact for i in catalogue):
        return ""
    return f"left out: {', '.join(absent)} (they need the generator's exact depth, which the test drives lack)"


def findings(results: dict[tuple[int | None, str], LayerResult], beams: list[int]) -> list[str]:
    """One line per beam count: the completed inputs that localise better than sparse beyond the spread, the best
    one's share of the sparse → exact gap, whether masking nconv by its confidence differs beyond the spread, and
    whether each fine-tuned input (``tuned_from``) differs from the input it was fine-tuned from."""
    lines = []
    exact = results.get((None, "exact"))
    robust = robust_columns(results, beams)[0] if results else {}
    robust_better = {}
    for (b, label), fields in robust.items():
        if b is not None and fields.get("robust_vs_sparse") == "better" and INPUT_OF.get(label) is not None \
                and INPUT_OF[label].completer:
            robust_better.setdefault(b, []).append(label)
    for b in sorted(beams, reverse=True):
        sparse = results.get((b, "sparse"))
        if sparse is None or not sparse.pairs:
            continue
        completed = [results[(b, i.label)] for i in _items(results) if i.completer and (b, i.label) in results
                     and results[(b, i.label)].pairs]
        better = [r.label for r in completed if _verdict(r, sparse) == "better"]
        scored = [r for r in completed if r.localisation is not None]
        best = min(scored, key=lambda r: r.localisation) if scored else None
        gap = _gap_closed(best, sparse, exact) if best is not None else None
        text = f"{b} beams: better than sparse beyond the spread: {', '.join(better) or 'none'}"
        text += f"; by the median interval: {', '.join(robust_better.get(b, [])) or 'none'}"
        if best is not None:
            text += f"; best completed input {best.label} ({best.localisation:.4f} vs sparse {sparse.localisation:.4f}"
            text += f", {100 * gap:.0f} % of the gap to exact)" if gap is not None else ")"
        masked, plain = results.get((b, "nconv masked")), results.get((b, "nconv"))
        if masked is not None and plain is not None and masked.pairs and plain.pairs:
            text += f"; nconv masked vs unmasked: {_verdict(masked, plain)}"
        for item in (i for i in _items(results) if i.tuned_from):
            tuned, base = results.get((b, item.label)), results.get((b, item.tuned_from))
            if tuned is not None and base is not None and tuned.pairs and base.pairs:
                text += f"; {item.label} vs {item.tuned_from}: {_verdict(tuned, base)}"
        lines.append(text)
    return lines


def _items(results: dict) -> list[BeamsInput]:
    """The inputs of the rows of ``results``, each once, in the order of their first row."""
    return [INPUT_OF[label] for label in dict.fromkeys(k[1] for k in results) if label in INPUT_OF]


def correlation(results: dict[tuple[int | None, str], LayerResult], drives: list[str], name: str = "beams") -> Table:
    """The rank correlation of each depth metric with localisation over every (row, drive) pair of the beams table's
    rows whose SLAM aligned the layer's own points (:func:`dcslam.report.correlation_table.correlation_table`): a
    measured-source row has the depth metrics of its layer's depth row and another SLAM, so it would count each
    layer twice, once for a question the metrics do not ask."""
    from dcslam.report.correlation_table import correlation_table

    threshold = next(iter(results.values())).failure_threshold if results else FAILURE_THRESHOLD
    depth_mode = {i.label for i in INPUT_OF.values() if i.sources != MEASURED}
    table = correlation_table(
        [(_row_name(key), result) for key, result in results.items() if key[1] in depth_mode],
        f"The {name} experiment: depth metrics against localisation over rows × {len(drives)} test drive(s)",
        threshold, depth_note="MAE / RMSE: against the annotated depth over every frame; " + (
            surface_note(list(results.values())) or "no surface errors scored"))
    table.notes.append("rows: those whose SLAM aligned the layer's own points (the measured-source rows, whose "
                       "depth is their depth rows', are left out)")
    return table


def per_drive_table(results: dict[tuple[int | None, str], LayerResult], name: str = "beams") -> Table:
    """Every figure of every row on every test drive (``results/table_beams_per_drive.csv``)."""
    from dcslam.report.scores import PER_DRIVE_KEYS

    columns = [Column("beams", "beams"), Column("input", "input"), Column("layer", "layer"), Column("seed", "seed"),
               Column("drive", "drive")] + [Column(k, k) for k in PER_DRIVE_KEYS] + [
        Column("vs_sparse_m", "vs sparse"), Column("failed_by_all", "failed by all")]
    beams = sorted({b for b, _ in results if b is not None}, reverse=True)
    top = beams[0] if beams else None
    failed_all = robust_columns(results, beams)[1] if beams else {}
    sparse = {b: drive_localisation(results[(b, "sparse")]) for b in beams
              if (b, "sparse") in results and results[(b, "sparse")].pairs}
    rows = []
    for (b, label), r in results.items():
        reference = sparse.get(b if b is not None else top, {})
        for seed, drive, values in r.per_drive_rows():
            here = values.get("localisation")
            rows.append({"beams": b if b is not None else "any", "input": label, "layer": seed_layer(r, seed),
                         "seed": seed, "drive": drive, **values,
                         # this run's localisation less the sparse input's on the drive (< 0: better than sparse)
                         "vs_sparse_m": None if here is None or drive not in reference else here - reference[drive],
                         "failed_by_all": drive in failed_all.get(b if b is not None else top, ())})
    return Table(f"The {name} experiment per drive", columns, rows)


def plot_localisation_vs_beams(path: Path | str, results: dict[tuple[int | None, str], LayerResult],
                               beams: list[int], force: bool = False) -> Path:
    """Localisation (mean over drives, bars: 95 % half-width, clipped above zero) against beam count, one line per
    input; the beam-independent inputs as horizontal lines with their interval as a band. Log-log axes."""
    from dcslam.io.atomic import atomic_output
    from dcslam.report.plots import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    xs = sorted(beams)
    per_beam = [item for item in _items(results) if item.per_beam]
    for i, item in enumerate(per_beam):
        points = [(b, results[(b, item.label)].localisation_spread())
                  for b in xs if (b, item.label) in results and results[(b, item.label)].pairs]
        if not points:
            continue
        offset = 0.03 * (i - (len(per_beam) - 1) / 2)  # the bars of different inputs a little apart
        x = [b * (1 + offset) for b, _ in points]
        mean = [s.mean for _, s in points]
        low = [0.0 if s.ci_low is None else s.mean - max(s.ci_low, 0.05 * s.mean) for _, s in points]
        high = [0.0 if s.ci_high is None else s.ci_high - s.mean for _, s in points]
        ax.errorbar(x, mean, yerr=[low, high], marker="os^vDPX"[i % 7], color=f"C{i % 10}", capsize=3, lw=1.4,
                    ls=":" if item.sources == MEASURED else "-", label=item.label)
    for j, item in enumerate(i for i in _items(results) if not i.per_beam):
        result = results.get((None, item.label))
        if result is None or not result.pairs:
            continue
        s = result.localisation_spread()
        colour = f"C{(len(per_beam) + j) % 10}"
        ax.axhline(s.mean, color=colour, ls="--", lw=1.2, label=f"{item.label} (any beam count)")
        if s.ci_low is not None:
            ax.axhspan(max(s.ci_low, 0.05 * s.mean), s.ci_high, color=colour, alpha=0.12)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xticks(xs, [str(b) for b in xs])
    ax.set_xlabel("LiDAR beams kept (of 64)")
    ax.set_ylabel("localisation error (m + rad, thesis metric; lower is better)")
    n = max((len(r.pairs) for r in results.values()), default=0)
    ax.set_title(f"Localisation against beam count: mean over {n} test drives, bars/bands 95 % interval", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    with atomic_output(path, force=force) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return Path(path)


@dataclass
class BeamsReport:
    """The beams table, its per-drive table, the rank correlation of its depth metrics with localisation and the
    files written."""

    table: Table
    per_drive: Table
    written: list[Path]
    correlation: Table | None = None


def build_beams_report(ws: Workspace, beams: list[int], drives: list[str], out_dir: Path | None = None,
                       force: bool = False, max_time_diff: float = EVO_MAX_TIME_DIFF_S,
                       failure_threshold: float = FAILURE_THRESHOLD, jobs: int = 1,
                       inputs: list[str] | None = None, name: str = "beams",
                       catalogue: tuple = INPUTS) -> BeamsReport:
    """Score every row (``inputs``: only the rows of these labels) and write ``table_beams.{md,csv}``,
    ``table_beams_per_drive.{md,csv}``, ``table_beams_correlation.{md,csv}`` and ``beams_localisation.png`` under
    ``out_dir`` (default ``results/``); nothing is written when an output exists without ``force``, or when rows
    were made with different SLAM settings (``jobs``: worker processes that score the rows). ``name`` and
    ``catalogue``: another experiment's files (``table_<name>*``, ``<name>_localisation.png``) and inputs."""
    from dcslam.io.atomic import write_text_atomic
    from dcslam.report.scores import check_outputs

    if not beams or not drives:
        raise DcslamError("the beams table needs at least one beam count and one test drive")
    out_dir = Path(out_dir) if out_dir else ws.results
    results = beams_results(ws, beams, drives, max_time_diff, failure_threshold, jobs, inputs, catalogue)
    table, per_drive = table_beams(results, beams, drives, name, catalogue), per_drive_table(results, name)
    ranks = correlation(results, drives, name)
    tables = {f"table_{name}": table, f"table_{name}_per_drive": per_drive, f"table_{name}_correlation": ranks}
    outputs = [out_dir / f"{name}.{ext}" for name in tables for ext in ("md", "csv")]
    plot = out_dir / f"{name}_localisation.png"
    check_outputs([*outputs, plot], force)
    written = []
    for name, t in tables.items():
        written.append(write_text_atomic(out_dir / f"{name}.md", t.to_markdown(), force=True))
        written.append(write_text_atomic(out_dir / f"{name}.csv", t.to_csv(), force=True))
    if any(r.pairs for r in results.values()):
        written.append(plot_localisation_vs_beams(plot, results, beams, force=True))
    return BeamsReport(table, per_drive, written, ranks)
