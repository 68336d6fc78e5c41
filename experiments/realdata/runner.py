"""Run ``ibik track`` on the benchmark's files and judge it: one variant on one clip, or a grid.

Variants: "ik" (eq. 3, blind), "pik" (the hierarchical QP without the image level) and "ibik<N>v"
(the same with the image criterion in the first N cameras). A run writes nothing but what
``ibik track`` writes; errors are eq. (9) against the raw mocap joints, residuals the distance of
each target keypoint in joints.trc to its target.

From Python (experiments/ on sys.path), with the rendered inputs cached on disk::

    from realdata.runner import run_one
    result = run_one("boxing_a", "ibik2v", settings={"criterion": "two-way"}, frames=40)
    print(result.joint_errors_mm, result.mean_mm)
"""

from __future__ import annotations

import ctypes
import dataclasses
import re
import shutil
import subprocess
import tempfile
import time
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from paper.section4 import DEFECT_MASK_FILTER_RADIUS

from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.exceptions import InputError, UnknownNameError
from ibik_pin.io.trc import read_trc, write_trc
from ibik_pin.tracking.settings import TrackingSettings
from realdata.clips import CLIPS, ESTIMATED
from realdata.inputs import CONDITIONS, ClipInputs, prepare_inputs

REPOSITORY = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPOSITORY.parent / "shared" / "data"
DEFAULT_CACHE = REPOSITORY / "out" / "real_mocap_cache"
JOINTS_OF_KIND = {"boxing": ("LElbow", "RElbow"), "walking": ("LKnee", "RKnee")}


def code_revision() -> str:
    """The repository's commit, with "+ local changes" when the library's files differ from it."""
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPOSITORY, capture_output=True,
                                text=True, check=True).stdout.strip()
        changed = subprocess.run(["git", "status", "--porcelain", "--", "ibik_pin"], cwd=REPOSITORY,
                                 capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + (" + local changes to ibik_pin" if changed else "")


def single_threaded_math() -> None:
    """Run OpenBLAS (numpy's linear algebra) and OpenMP on one thread in this process, from now on.

    On this shared 2-core machine the solvers' small SVDs (75 x 42) took 0.4 ms each on one thread
    but up to 140 ms with OpenBLAS's threads waiting for busy cores: 20.7 s against 0.46 s of SVD
    in a 40-frame IK run of boxing_a. The thread counts are set through the libraries' own entry
    points (as threadpoolctl does), since numpy is already loaded; where that fails nothing changes.
    """
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return
    setters = {"openblas": ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                            "openblas_set_num_threads"),
               "libgomp": ("omp_set_num_threads",)}
    for path in dict.fromkeys(line.split()[-1] for line in maps):
        kind = next((kind for kind in setters if kind in Path(path).name.lower()), None)
        if kind is None:
            continue
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        function = next((getattr(library, s) for s in setters[kind] if hasattr(library, s)), None)
        if function is not None:
            function(ctypes.c_int(1))


@dataclass(frozen=True)
class Variant:
    """A way of tracking: name as in the tables, solver scheme, cameras used (0: blind)."""

    name: str
    method: str
    views: int

    @property
    def label(self) -> str:
        return f"IBIK {self.views}v" if self.views else self.name.upper()


def variant(name: str) -> Variant:
    """"ik", "pik", or "ibik<N>v" / "ibik<N>" (the image criterion in N views)."""
    if name in ("ik", "pik"):
        return Variant(name, "ik" if name == "ik" else "qp", 0)
    match = re.fullmatch(r"ibik(\d+)v?", name)
    if match and int(match.group(1)) >= 1:
        return Variant(f"ibik{int(match.group(1))}v", "qp", int(match.group(1)))
    raise UnknownNameError(f"variant: expected ik, pik or ibik<N>v (e.g. ibik2v), got {name!r}")


# Settings whose default is None and whose value is otherwise a number.
FLOAT_OR_NONE = ("step_tolerance", "target_step_tolerance")


def parse_settings(pairs: typing.Iterable[str]) -> dict:
    """TrackingSettings overrides from "key=value" strings, each value typed like the field's default.

    Raises:
        InputError: no "=", an unknown field, or a value that does not parse as the field's type.
    """
    fields = {field.name: field for field in dataclasses.fields(TrackingSettings)}
    overrides = {}
    for pair in pairs:
        key, separator, text = pair.partition("=")
        key, text = key.strip(), text.strip()
        if not separator:
            raise InputError(f"--set {pair!r}: expected key=value")
        if key not in fields:
            raise InputError(f"--set {pair!r}: unknown TrackingSettings field {key!r}; known: {', '.join(fields)}")
        default = getattr(TrackingSettings(), key)
        try:
            if isinstance(default, bool):
                if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError(text)
                value = text.lower() in ("true", "1", "yes")
            elif isinstance(default, (int, float, str)):
                value = type(default)(text)
            elif default is None and key in FLOAT_OR_NONE:
                value = None if text.lower() == "none" else float(text)
            else:
                value = text
        except ValueError:
            raise InputError(f"--set {pair!r}: expected a {type(default).__name__} like the default "
                             f"{default!r}") from None
        overrides[key] = value
    return overrides


def tracking_settings(chosen: Variant, condition: str, overrides: dict | None = None) -> TrackingSettings:
    """The variant's settings; with defects IBIK votes masks over 3 frames (Section 4); then overrides."""
    vote = DEFECT_MASK_FILTER_RADIUS if condition == "defects" and chosen.views else 0
    settings = TrackingSettings(method=chosen.method, use_image=chosen.views > 0, mask_filter_radius=vote)
    return dataclasses.replace(settings, **(overrides or {}))


@dataclass
class RunResult:
    """One variant on one clip in one condition.

    Attributes:
        errors: (F, 4) distance of LElbow, RElbow, LKnee, RKnee to the truth per frame [m].
        residuals_mm: target keypoint -> mean distance of its joints.trc position to its target [mm].
        wall_seconds: the whole run_track call [s]; solve_fps: its solve frames per second;
        loop_fps: the frames per second of its whole frame loop (silhouettes read, support images).
    """

    clip: str
    kind: str
    variant: str
    condition: str
    errors: np.ndarray
    residuals_mm: dict[str, float]
    wall_seconds: float
    solve_fps: float
    loop_fps: float

    @property
    def joint_errors_mm(self) -> dict[str, float]:
        return {joint: float(np.mean(self.errors[:, k]) * 1000.0) for k, joint in enumerate(ESTIMATED)}

    @property
    def mean_mm(self) -> float:
        return float(np.mean(self.errors) * 1000.0)

    @property
    def judged_mm(self) -> float:
        """The joints the paper judges on this kind of clip: elbows (boxing) or knees (walking)."""
        errors = self.joint_errors_mm
        return float(np.mean([errors[joint] for joint in JOINTS_OF_KIND[self.kind]]))

    def row(self) -> dict:
        return {"clip": self.clip, "kind": self.kind, "variant": self.variant, "condition": self.condition,
                "errors_mm": self.joint_errors_mm, "mean_mm": self.mean_mm, "judged_mm": self.judged_mm,
                "residuals_mm": self.residuals_mm, "wall_seconds": self.wall_seconds, "solve_fps": self.solve_fps,
                "loop_fps": self.loop_fps}


def run_variant(inputs: ClipInputs, chosen: Variant, condition: str, overrides: dict | None = None,
                out: Path | None = None, drop_targets: typing.Sequence[str] = (),
                target_filter: str | float | None = None, trial_lengths: str | None = None) -> RunResult:
    """``ibik track`` on the clip's files as a user runs it (`target_filter`, `trial_lengths`: its
    options of those names; None: its defaults).

    Args:
        out: where its outputs go (None: a temporary folder, removed afterwards).
        drop_targets: target keypoints left out of the targets file (e.g. LBigToe, RBigToe: with
            the ankle and the toe both targets, the model's 6-DOF leg has no swivel left).
        target_filter: ``ibik track --target-filter`` (off, auto or a cutoff in Hz; None: its default).
    """
    if condition not in CONDITIONS:
        raise UnknownNameError(f"condition: expected one of {', '.join(CONDITIONS)}, got {condition!r}")
    if chosen.views > len(inputs.cameras):
        raise InputError(f"variant {chosen.name}: {chosen.views} views, the rig has {len(inputs.cameras)}")
    unknown = [name for name in drop_targets if name not in inputs.target_names]
    if unknown:
        raise UnknownNameError(f"drop_targets: {unknown} are not targets; targets: {', '.join(inputs.target_names)}")
    single_threaded_math()
    scratch = Path(tempfile.mkdtemp(prefix="real_mocap_"))
    out = scratch / "run" if out is None else Path(out)
    targets = read_trc(inputs.targets(condition))
    targets_path = inputs.targets(condition)
    if drop_targets:
        kept = [k for k, name in enumerate(targets.marker_names) if name not in drop_targets]
        targets = dataclasses.replace(targets, marker_names=[targets.marker_names[k] for k in kept],
                                      positions=targets.positions[:, kept])
        targets_path = scratch / "targets.trc"
        write_trc(targets_path, targets)
    job = TrackJob(
        targets=targets_path, out=out, static=inputs.static,
        calibration=inputs.calibration if chosen.views else None,
        masks=inputs.masks(condition) if chosen.views else None,
        cameras=inputs.cameras[:chosen.views] if chosen.views else None,
        settings=tracking_settings(chosen, condition, overrides), quiet=True,
        **({} if target_filter is None else {"target_filter": target_filter}),
        **({} if trial_lengths is None else {"trial_lengths": trial_lengths}),
    )
    started = time.perf_counter()
    try:
        report = run_track(job)
        wall = time.perf_counter() - started
        estimate = read_trc(out / "joints.trc").in_metres()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    targets = targets.in_metres()

    def positions(data, names: typing.Sequence[str]) -> np.ndarray:
        return data.positions[:, [data.marker_names.index(name) for name in names]]

    truth = inputs.truth[:, [inputs.truth_names.index(name) for name in ESTIMATED]]
    errors = np.linalg.norm(positions(estimate, ESTIMATED) - truth, axis=2)
    distances = np.linalg.norm(positions(estimate, targets.marker_names) - targets.positions, axis=2)
    residuals = {name: float(np.nanmean(distances[:, k]) * 1000.0) for k, name in enumerate(targets.marker_names)}
    return RunResult(inputs.spec.name, inputs.spec.kind, chosen.name, condition, errors, residuals, wall,
                     float(report["solve_frames_per_second"]), float(report["frames_per_second"]))


def run_one(clip: str, variant_name: str = "ibik2v", condition: str = "clean", frames: int = 120,
            settings: dict | None = None, data: Path = DEFAULT_DATA, cache: Path = DEFAULT_CACHE,
            out: Path | None = None, drop_targets: typing.Sequence[str] = ()) -> RunResult:
    """One variant on one clip of :data:`CLIPS` (inputs rendered once into `cache`, then reused).

    Args:
        clip: e.g. "cmu35_01" or "boxing_a".
        variant_name: "ik", "pik" or "ibik<N>v".
        condition: "clean" or "defects".
        frames: frames of the window at 60 Hz.
        settings: TrackingSettings overrides, e.g. {"criterion": "two-way", "iterations": 30}.
        out: where ``ibik track`` writes (None: a temporary folder).
        drop_targets: target keypoints to leave out, e.g. ("LBigToe", "RBigToe").
    """
    if clip not in CLIPS:
        raise UnknownNameError(f"clip: expected one of {', '.join(CLIPS)}, got {clip!r}")
    inputs = prepare_inputs(CLIPS[clip], Path(data), frames, Path(cache))
    return run_variant(inputs, variant(variant_name), condition, settings, out, drop_targets)


def _mean(values: typing.Iterable[float]) -> float | None:
    values = list(values)
    return float(np.mean(values)) if values else None


def summarize(results: typing.Sequence[RunResult]) -> dict:
    """Aggregates as the paper reports them, per condition and variant: elbows over the boxing
    clips, knees over the walking clips (means of the clips' means), all four joints over every
    clip; and each target keypoint's residual averaged over the clips."""
    summary: dict = {}
    for condition in dict.fromkeys(r.condition for r in results):
        for name in dict.fromkeys(r.variant for r in results):
            runs = [r for r in results if r.condition == condition and r.variant == name]
            if not runs:
                continue
            keypoints = list(dict.fromkeys(k for r in runs for k in r.residuals_mm))
            summary.setdefault(condition, {})[name] = {
                "elbows_boxing_mm": _mean(r.judged_mm for r in runs if r.kind == "boxing"),
                "knees_walking_mm": _mean(r.judged_mm for r in runs if r.kind == "walking"),
                "all_four_mm": _mean(r.mean_mm for r in runs),
                "residuals_mm": {k: _mean(r.residuals_mm[k] for r in runs if k in r.residuals_mm) for k in keypoints},
                "clips": [r.clip for r in runs],
            }
    return summary


def _cell(value: float | None) -> str:
    return "-" if value is None else f"{value:.1f}"


def _label(name: str) -> str:
    return variant(name).label


def markdown(results: typing.Sequence[RunResult], summary: dict, header: str) -> str:
    """The tables: aggregated, per clip, and the target residuals per keypoint."""
    lines = [header, "", "## Mean error [mm] as the paper aggregates it", "",
             "Elbows over the boxing clips, knees over the walking clips (mean of the clips' means), "
             "and all four joints (LElbow, RElbow, LKnee, RKnee) over every clip.", ""]
    conditions = list(summary)
    lines.append("| variant | " + " | ".join(f"{c}: elbows (boxing) | {c}: knees (walking) | {c}: all four"
                                              for c in conditions) + " |")
    lines.append("| --- |" + " ---: |" * (3 * len(conditions)))
    for name in dict.fromkeys(r.variant for r in results):
        cells = []
        for condition in conditions:
            row = summary[condition].get(name, {})
            cells += [_cell(row.get("elbows_boxing_mm")), _cell(row.get("knees_walking_mm")),
                      _cell(row.get("all_four_mm"))]
        lines.append(f"| {_label(name)} | " + " | ".join(cells) + " |")
    for condition in conditions:
        lines += ["", f"## Per clip, {condition} [mm]", "",
                  "| clip | variant | " + " | ".join(ESTIMATED) + " | mean | run [s] | frames/s | solve fps |",
                  "| --- | --- |" + " ---: |" * (len(ESTIMATED) + 4)]
        for r in results:
            if r.condition == condition:
                errors = r.joint_errors_mm
                lines.append(f"| {r.clip} | {_label(r.variant)} | " + " | ".join(_cell(errors[j]) for j in ESTIMATED)
                             + f" | {_cell(r.mean_mm)} | {r.wall_seconds:.1f} | {r.loop_fps:.0f} | {r.solve_fps:.0f} |")
    keypoints = list(dict.fromkeys(k for r in results for k in r.residuals_mm))
    lines += ["", "## Target residual per keypoint [mm]", "",
              "Distance of each target keypoint in joints.trc to its target, mean over frames and clips.", "",
              "| condition | variant | " + " | ".join(keypoints) + " |",
              "| --- | --- |" + " ---: |" * len(keypoints)]
    for condition in conditions:
        for name, row in summary[condition].items():
            lines.append(f"| {condition} | {_label(name)} | "
                         + " | ".join(_cell(row["residuals_mm"].get(k)) for k in keypoints) + " |")
    return "\n".join(lines) + "\n"
