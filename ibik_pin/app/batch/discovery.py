"""Finding the trials under a session folder, their calibration and their participant's subject.

Layout (Pose2Sim's, with what `ibik track` needs)::

    ROOT/.../calibration/Calib*            the cameras: the nearest calibration in the trial's folder,
                                           its calibration/ sub-folder, or the same in a parent (any
                                           format io.calibration reads: Pose2Sim or Anipose TOML,
                                           Qualisys .qca.txt, EasyMocap intri.yml + extri.yml)
    ROOT/.../PARTICIPANT/subject.urdf      a calibrated model (`ibik calibrate`), or
    ROOT/.../PARTICIPANT/*static*/x.trc    a static trial, calibrated once for all the participant's trials
    ROOT/.../PARTICIPANT/TRIAL/x.trc       the targets (or TRIAL/pose-3d/x.trc), and
    ROOT/.../PARTICIPANT/TRIAL/masks/      one sub-folder of masks per camera, or
    ROOT/.../PARTICIPANT/TRIAL/videos/     one video per camera (and background/ frames, if any)

A trial is a folder, not a static one, that holds a TRC matching the targets pattern (itself or in
pose-3d/), or a videos/ folder of videos (then, without a TRC, the targets are triangulated from
the videos, as `ibik track --videos --calibration` without --targets does); its participant's
folder is its parent. ROOT itself may be the trial (a Pose2Sim project of one trial): it is then
named after ROOT's folder. A calibration is a file named calib* (TOML, .qca.txt, YAML), or any
file of calibration/ that io.calibration reads; where a folder holds several, its one TOML is taken
(Pose2Sim keeps the Qualisys file it converted beside its TOML). Anything ambiguous (two TRC files,
two calibrations) is the trial's problem, recorded for that trial alone.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Subject", "Trial", "find_trials"]

TARGET_FOLDERS = ("", "pose-3d")  # where a trial's TRC may be: the trial's folder or Pose2Sim's pose-3d/
CALIBRATION_SUFFIXES = (".toml", ".txt", ".yml", ".yaml")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v")  # as app.silhouette_files reads them


@dataclass(frozen=True)
class Subject:
    """A participant's model: a calibrated URDF to use as it is, or a static trial to calibrate once.

    Attributes:
        folder: the participant's folder, relative to ROOT.
        model: a URDF found in the participant's folder, or None.
        static: a static trial's TRC, or None.
    """

    folder: Path
    model: Path | None = None
    static: Path | None = None


@dataclass(frozen=True)
class Trial:
    """One trial's inputs, absolute paths (None where not found).

    Attributes:
        name: the trial's folder relative to ROOT: its outputs go to OUTROOT/name.
        targets: the targets' TRC.
        calibration: the Pose2Sim calibration TOML.
        masks, videos, background: the silhouettes' source folders.
        subject: the participant's subject, None when it has neither URDF nor static trial.
        problem: why the trial cannot run, found before running it; None when it can.
    """

    name: Path
    targets: Path | None
    calibration: Path | None
    masks: Path | None
    videos: Path | None
    background: Path | None
    subject: Subject | None
    problem: str | None = None


def _is_static(name: str) -> bool:
    return "static" in name.lower()


def _child(folder: Path, name: str) -> Path | None:
    """The sub-folder of `folder` called `name`, ignoring case."""
    found = [path for path in sorted(folder.iterdir()) if path.is_dir() and path.name.lower() == name]
    return found[0] if found else None


def _trc_files(folder: Path, pattern: str) -> list[Path]:
    """The files matching `pattern` in `folder` and its pose-3d/ sub-folder."""
    found: list[Path] = []
    for sub in TARGET_FOLDERS:
        where = _child(folder, sub) if sub else folder
        if where is not None:
            found += [p for p in sorted(where.glob(pattern)) if p.is_file()]
    return found


def _reads_as_calibration(path: Path) -> bool:
    from ibik_pin.exceptions import IbikError
    from ibik_pin.io.calibration import read_calibration

    try:
        return bool(read_calibration(path))
    except (IbikError, OSError, ValueError):
        return False


def _calibrations_in(folder: Path) -> list[Path]:
    """The calibrations of a folder and its calibration/ sub-folder (see the module docstring)."""
    sub = _child(folder, "calibration")
    found = []
    for place in [folder] + ([sub] if sub is not None else []):
        files = [p for p in sorted(place.iterdir()) if p.is_file() and p.suffix.lower() in CALIBRATION_SUFFIXES]
        names = {p.name.lower() for p in files}
        for path in files:
            name = path.name.lower()
            if name == "extri.yml" and "intri.yml" in names:
                continue  # EasyMocap's pair is one calibration, read from either file
            if name.startswith("calib") or (place == sub and _reads_as_calibration(path)):
                found.append(path)
    tomls = [path for path in found if path.suffix.lower() == ".toml"]
    return tomls if len(found) > 1 and len(tomls) == 1 else found


def _has_videos(folder: Path) -> bool:
    """Whether a videos/ folder holds a video, directly or in a camera's sub-folder."""
    return any(path.suffix.lower() in VIDEO_SUFFIXES and path.is_file()
               for place in [folder, *(p for p in folder.iterdir() if p.is_dir())] for path in place.iterdir())


def _nearest_calibration(trial: Path, root: Path) -> tuple[Path | None, str | None]:
    """The calibration nearest to the trial, walking up to ROOT; a problem if one folder has two."""
    folder = trial
    while True:
        found = _calibrations_in(folder)
        if len(found) > 1:
            return None, f"several calibration files in {folder}: {', '.join(p.name for p in found)}"
        if found:
            return found[0], None
        if folder == root:
            return None, None
        folder = folder.parent


def _subject(participant: Path, root: Path, pattern: str) -> tuple[Subject | None, str | None]:
    models = sorted(p for p in participant.glob("*.urdf") if p.is_file())
    if len(models) > 1:
        return None, f"several URDF files in {participant}: {', '.join(p.name for p in models)}"
    name = participant.relative_to(root)
    if models:
        return Subject(name, model=models[0]), None
    statics = [p for p in sorted(participant.glob("*.trc")) if _is_static(p.name)]
    for folder in sorted(participant.iterdir()):
        if folder.is_dir() and _is_static(folder.name):
            statics += _trc_files(folder, pattern)
    if len(statics) > 1:
        return None, f"several static trials in {participant}: {', '.join(str(p) for p in statics)}"
    return (Subject(name, static=statics[0]), None) if statics else (None, None)


def find_trials(root: Path, pattern: str = "*.trc", exclude: Path | None = None) -> list[Trial]:
    """Every trial under `root` (absolute), sorted by name; `exclude` (the output folder) is skipped.

    Args:
        root: the session folder, absolute.
        pattern: glob of the targets' TRC file name in a trial.
        exclude: a folder under `root` not to search, absolute.
    """
    trials = []
    for current, folders, _ in os.walk(root):
        folder = Path(current)
        folders[:] = sorted(name for name in folders if not name.startswith(".") and not _is_static(name)
                            and folder / name != exclude)
        if folder == exclude:
            continue
        targets = [path for path in _trc_files(folder, pattern) if not _is_static(path.name)]
        masks, videos = _child(folder, "masks"), _child(folder, "videos")
        if not targets and not (videos is not None and _has_videos(videos)):
            continue
        folders[:] = []  # a trial holds no other trial
        problems = []
        if len(targets) > 1:
            problems.append(f"several TRC files match {pattern!r}: {', '.join(str(p) for p in targets)} "
                            "(choose one with --targets PATTERN)")
        calibration, problem = _nearest_calibration(folder, root)
        if not targets and calibration is None and problem is None:
            problem = (f"no calibration found for the videos in {videos} (a calib* file or a calibration/ "
                       f"folder, in the trial's folder or above it up to ROOT) and no TRC matching {pattern!r}")
        subject, subject_problem = _subject(folder.parent if folder != root else root, root, pattern)
        problems += [p for p in (problem, subject_problem) if p]
        trials.append(Trial(
            name=folder.relative_to(root) if folder != root else Path(root.name),
            targets=targets[0] if len(targets) == 1 else None,
            calibration=calibration, masks=masks, videos=None if masks is not None else videos,
            background=_child(folder, "background") if masks is None and videos is not None else None,
            subject=subject, problem="; ".join(problems) or None,
        ))
    return trials
