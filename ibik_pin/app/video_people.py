"""Several people in --videos: every view's people detected in worker processes (each decodes its
own video: frames never cross a process boundary), the detections associated across views into
people, and the person `ibik track` follows chosen (--person).

The detection of one view is sequential (MediaPipe's trackers follow their people frame to frame),
so the views are spread over up to as many processes as the machine gives this one cores.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import queue
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ibik_pin.app.people_worker import detect_one, read_message
from ibik_pin.exceptions import IbikError, InputError, UnreconciledViewsError
from ibik_pin.readahead.view_workers import usable_cores
from ibik_pin.vision.people import DetectionSettings, ViewPeople
from ibik_pin.vision.person_association import PeopleTracks, associate_people

__all__ = ["PERSON_RULE", "DetectedPeople", "PeopleReport", "chosen_person", "detect_people_in_videos",
           "parse_person"]

PERSON_RULE = ("the person seen in the most view-frames (detections two views or more agree on, summed over "
               "views and frames), ties to the one nearest the point the cameras aim at")


@dataclass
class PeopleReport:
    """Who was in the videos, and whom `ibik track` followed (report.json's "people").

    Attributes:
        found: the number of people the views agree on (two views or more).
        tracked: the person followed, 1-based in the ranking of `view_frames`.
        rule: how the default person is chosen.
        view_frames: per person (ranked), detections associated to that person.
        frames_triangulated: per person, frames where two views or more agree on that person.
        unassociated_per_view: per camera, detections no other view confirms (left out).
        pair_error_median_m: median reprojection error of the associated pairs of detections [m].
        max_people: trackers per view (DetectionSettings.max_people).
        detect_height: the height the frames were fed to the detector at [px] (0: full size).
        workers: processes the views were detected in.
    """

    found: int
    tracked: int
    rule: str = PERSON_RULE
    view_frames: list[int] = field(default_factory=list)
    frames_triangulated: list[int] = field(default_factory=list)
    unassociated_per_view: dict[str, int] = field(default_factory=dict)
    pair_error_median_m: float | None = None
    max_people: int = 0
    detect_height: int = 0
    workers: int = 1


@dataclass
class DetectedPeople:
    """Every view's people and their association, with the time each step took.

    Attributes:
        names: the cameras, in the order of `views`.
        views: per camera, the people its trackers followed.
        tracks: the association across views and time.
        seconds: "decode" and "detection" summed over the views (processor time in the workers),
            "detection_wall" the wall time of the parallel detection, "association".
        workers: the processes used.
        settings: the detector's.
    """

    names: list[str]
    views: list[ViewPeople]
    tracks: PeopleTracks
    seconds: dict[str, float]
    workers: int
    settings: DetectionSettings

    def report(self, person: int) -> PeopleReport:
        """The PeopleReport with `person` (0-based) followed."""
        errors = self.tracks.pair_errors_m
        return PeopleReport(found=self.tracks.count, tracked=person + 1, view_frames=list(self.tracks.view_frames),
                            frames_triangulated=list(self.tracks.frames),
                            unassociated_per_view=dict(zip(self.names, self.tracks.unassociated, strict=True)),
                            pair_error_median_m=float(np.median(errors)) if errors else None,
                            max_people=self.settings.max_people, detect_height=self.settings.detect_height,
                            workers=self.workers)


def parse_person(text: str | int) -> str | int:
    """--person's value: "auto", "all" or a person's number (1 = the default rule's first)."""
    if isinstance(text, int) and not isinstance(text, bool):
        number = text
    elif isinstance(text, str) and text in ("auto", "all"):
        return text
    elif isinstance(text, str) and text.strip().isdigit():
        number = int(text)
    else:
        raise InputError(f"--person: expected auto, all or a person's number (1, 2, ...), found {text!r}")
    if number < 1:
        raise InputError(f"--person: expected auto, all or a person's number (1, 2, ...), found {text!r}")
    return number


def chosen_person(person: str | int, tracks: PeopleTracks) -> int:
    """The 0-based person --person names ("auto": the rule's first)."""
    if tracks.count == 0:
        raise UnreconciledViewsError(
            "--videos: no person is seen by two cameras that agree on where they are: the views cannot be "
            "reconciled (a wrong calibration, unsynchronised videos, or nobody in view)")
    if person == "auto":
        return 0
    if not isinstance(person, int) or not 1 <= person <= tracks.count:
        raise InputError(f"--person: expected auto, all or 1 to {tracks.count} (the people the views agree on), "
                         f"found {person!r}")
    return person - 1


def _start_worker(jobs: list[tuple[int, Path]], settings: DetectionSettings,
                  messages: queue.Queue) -> subprocess.Popen:
    """A worker process (app.people_worker) detecting `jobs`; a thread puts its messages on
    `messages`, then ("ended", process) when its pipe closes."""
    read_end, write_end = os.pipe()
    package_root = str(Path(__file__).resolve().parents[2])
    search_path = os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")]))
    try:
        process = subprocess.Popen([sys.executable, "-m", "ibik_pin.app.people_worker", str(write_end)],
                                   stdin=subprocess.PIPE, pass_fds=(write_end,),
                                   env=dict(os.environ, PYTHONPATH=search_path))
    except BaseException:
        os.close(read_end)
        raise
    finally:
        os.close(write_end)

    def relay() -> None:
        with os.fdopen(read_end, "rb") as pipe:
            while (message := read_message(pipe)) is not None:
                messages.put(message)
        messages.put(("ended", process))

    threading.Thread(target=relay, name="ibik-people-relay", daemon=True).start()
    if process.stdin is not None:
        with process.stdin:
            pickle.dump((jobs, settings), process.stdin, protocol=pickle.HIGHEST_PROTOCOL)
    return process


def detect_people_in_videos(videos: dict[str, Path], cameras: Sequence, frame_rate: float, *, progress: bool,
                            total_frames: int | None = None, settings: DetectionSettings | None = None,
                            workers: int | None = None) -> DetectedPeople:
    """Detect every camera's people (worker processes: `workers`, default the usable cores, at
    most one per camera) and associate them across views and time.

    Args:
        videos: camera name -> its video.
        cameras: the calibrated cameras (their order is the result's).
        frame_rate: the videos' frame rate [Hz].
        progress: draw a progress bar of the frames detected (when stderr is a terminal).
        total_frames: the frames to expect over all videos (the bar's total), if known.
    """
    settings = settings if settings is not None else DetectionSettings()
    names = [camera.name for camera in cameras]
    workers = max(1, min(workers or usable_cores(), len(names)))
    if multiprocessing.current_process().daemon:  # a pool's worker: the pool already spreads trials over the cores
        workers = 1
    views: list[ViewPeople | None] = [None] * len(names)
    decode = detection = 0.0
    start = time.perf_counter()
    with tqdm(total=total_frames, desc="people and silhouettes", unit="frame",
              disable=None if progress else True) as bar:
        if workers == 1:
            for index, name in enumerate(names):
                people, seconds_decode, seconds_detect = detect_one(videos[name], settings, bar.update)
                views[index], decode, detection = people, decode + seconds_decode, detection + seconds_detect
        else:
            messages: queue.Queue = queue.Queue()
            shares = [[(index, videos[name]) for index, name in enumerate(names) if index % workers == worker]
                      for worker in range(workers)]
            processes: list[subprocess.Popen] = []
            try:
                for share in shares:
                    processes.append(_start_worker(share, settings, messages))
                while any(view is None for view in views):
                    message = messages.get()
                    if message[0] == "frames":
                        bar.update(message[1])
                    elif message[0] == "done":
                        _, index, people, seconds_decode, seconds_detect = message
                        views[index], decode, detection = people, decode + seconds_decode, detection + seconds_detect
                    elif message[0] == "ended":
                        share = shares[processes.index(message[1])]
                        if any(views[index] is None for index, _ in share):
                            raise IbikError("--videos: a detection process ended without its result (exit code "
                                            f"{message[1].wait()})")
                    else:
                        raise InputError(message[1])
            finally:
                unfinished = any(view is None for view in views)  # an error or an interruption ended the wait
                for process in processes:
                    if unfinished and process.poll() is None:
                        process.kill()
                    process.wait()
    wall = time.perf_counter() - start
    counts = {name: view.frames for name, view in zip(names, views, strict=True) if view is not None}
    if len(set(counts.values())) > 1:
        raise InputError(f"--videos: the cameras' videos have different frame counts {counts}; "
                         "they must be synchronised and of equal length")
    detected = [view for view in views if view is not None]
    start = time.perf_counter()
    tracks = associate_people(cameras, detected, frame_rate)
    seconds = {"decode": decode, "detection": detection, "detection_wall": wall,
               "association": time.perf_counter() - start}
    return DetectedPeople(names, detected, tracks, seconds, workers, settings)
