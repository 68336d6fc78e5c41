"""The `ibik` command: `ibik track` on the user's files, `ibik calibrate` a subject's model on a static
trial, `ibik demo` on data the repository ships.

Bad input ends with one line on stderr and exit code 2; nothing half-written is left in OUTDIR.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

# The solvers factor many tiny matrices (at most 42 x 42); OpenBLAS threads only add overhead to
# those, and on a loaded machine they make each factorisation 20-100 times slower. The setting
# takes effect only before numpy is first imported, hence here, above every import that brings
# numpy in; and only when this process is the `ibik` command, since a library must leave the
# environment of the program that imports it alone. A user's own setting wins.
if __name__ == "__main__" or Path(sys.argv[0]).stem == "ibik":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import contextlib
import signal
import threading
import time
import types
import typing
import warnings
from typing import TYPE_CHECKING

from ibik_pin.app.batch.command import add_batch_arguments
from ibik_pin.exceptions import IbikError, InputError
from ibik_pin.solvers import SOLVERS

if TYPE_CHECKING:
    from collections.abc import Iterator

    from ibik_pin.app.job import TrackJob

# The subcommands' modules (tracking, I/O, rendering, plots, the demo's synthetic data) are
# imported by the handlers that need them, so that `ibik --help` and argument errors answer at
# once.


def _add_track_arguments(parser: argparse.ArgumentParser) -> None:
    # Paths stay text: TrackJob checks and converts them, and an empty one must reach it as such
    # (Path("") is the current folder).
    parser.add_argument("--targets",
                        help="OpenSim TRC of 3D keypoints (Pose2Sim names), m or mm, or a C3D file (see "
                             "--c3d-mapping); without it, --videos and "
                             "--calibration: the keypoints are detected in every view and triangulated")
    parser.add_argument("--static", help="TRC (or C3D) of a static trial, to scale the model")
    parser.add_argument("--c3d-mapping", metavar="MAPPING.toml",
                        help="for C3D --targets/--static: a [keypoints] table of keypoint = [markers], each "
                             "keypoint the mean of its markers (default: markers named as keypoints, Vicon "
                             "BodyBuilder's joint points or Plug-in Gait markers)")
    parser.add_argument("--calibration", help="Pose2Sim calibration TOML")
    sources = parser.add_mutually_exclusive_group()
    sources.add_argument("--masks", help="folder with one sub-folder of masks per camera")
    sources.add_argument("--videos", help="folder with one video per camera")
    parser.add_argument("--background", help="frames of the empty scene (with --videos and --segmenter mog2)")
    parser.add_argument("--segmenter", choices=("auto", "mediapipe", "mog2"), default="auto",
                        help="silhouettes from --videos: mediapipe (MediaPipe Pose's person segmentation), mog2 "
                             "(background subtraction); auto (default): mediapipe where installed")
    parser.add_argument("--triangulated-limbs", action="store_true",
                        help="without --targets: the triangulated elbows and knees become targets below the "
                             "image (default: left to the image)")
    parser.add_argument("--refit-cameras",
                        help="comma-separated cameras that slipped since the calibration: each is turned to meet "
                             "the other views' triangulated keypoints (with --videos, MediaPipe and three cameras "
                             "or more; report.json's extrinsics shows each camera's disagreement; the cameras are "
                             "written to calibration_refitted.toml)")
    parser.add_argument("--person", default="auto",
                        help="with --videos: whom to track among the people the views agree on: auto (default: "
                             "the person seen in the most view-frames), a number (1 = that rule's first, 2 the "
                             "next, ...; report.json's people lists them), or all (each into OUT/person_N)")
    parser.add_argument("--cameras", help="comma-separated subset of the calibration's cameras")
    parser.add_argument("--model", help="URDF of the human (default: example-robot-data's)")
    parser.add_argument("--trial-lengths", choices=("off", "reach", "images"), default="images",
                        help="reach: lengthen a limb whose calibrated segments cannot reach its targets on this "
                             "trial (joint centres from markers are not rigid across takes); images: each leg's "
                             "length chosen on the silhouettes (two views or more), the arms by reach; "
                             "report.json gives each segment's change (default: images; with fewer than two views "
                             "or --no-image, reach)")
    parser.add_argument("--target-filter", default="auto", metavar="auto|off|HZ",
                        help="low-pass each target keypoint over time (zero-lag 4th-order Butterworth): auto "
                             "chooses each keypoint's cutoff from the trial's residual analysis, a number is the "
                             "cutoff in Hz; report.json's target_filter gives the cutoffs and the change "
                             "(default: auto; noise-free or already filtered keypoints are left nearly as they are)")
    parser.add_argument("--swivel-cutoff", default="6", metavar="HZ|off",
                        help="once every frame is solved, low-pass the free elbows' and knees' swivels about their "
                             "limbs' ends over the trial at this cutoff in Hz, each joint kept on its circle (the "
                             "frame-to-frame jitter of the image's peak); report.json's swivel_smoothing says how "
                             "far they moved (default: 6, the band of human joint motion; off: each frame's own)")
    parser.add_argument("--method", choices=sorted(SOLVERS), default="qp",
                        help="solver scheme (default: qp, the hierarchical QP with joint limits)")
    parser.add_argument("--qp-solver", metavar="NAME",
                        help="backend of --method qp's level QPs: active_set (default; the compiled primal "
                             "active-set method), proxsuite, or a solver qpsolvers has installed (daqp, proxqp, "
                             "...); a stack file's qp_solver key sets it too")
    parser.add_argument("--step-tolerance", type=float, metavar="RAD",
                        help="end a frame's solve early once a step moves the joints less than this "
                             "(norm of dq); report.json gives the mean steps per frame (default: always "
                             "--iterations)")
    parser.add_argument("--image-stop", choices=("peak", "count"), default="peak",
                        help="where a frame's image steps end: peak (default): once the image criterion "
                             "no longer rises, at the best step, or after --iterations; count: always "
                             "--iterations steps, as in the paper (report.json gives the mean steps per frame)")
    parser.add_argument("--no-image", action="store_true",
                        help="the same solve without the image criterion (blind baseline)")
    parser.add_argument("--iterations", type=int, default=15, help="solver steps per frame")
    parser.add_argument("--mask-filter", type=int, default=0, metavar="R",
                        help="vote each silhouette pixel over the 2R+1 frames around it, to remove "
                             "segmentation flicker (default 0: off)")
    # The tracker's CRITERIA, written here so that `ibik --help` need not import the tracker.
    parser.add_argument("--criterion", choices=("paper", "two-way"), default="two-way",
                        help="image criterion: two-way (default), the overlap of eq. (5)-(6) plus the "
                             "silhouette's medial axis explained by the skeleton; paper: the overlap alone")
    parser.add_argument("--swivel-search", action=argparse.BooleanOptionalAction, default=True,
                        help="each frame, search every free elbow's and knee's swivel on the image "
                             "criterion and hold it at a clearly better one (default: on; runs only when "
                             "two views cross)")
    parser.add_argument("--image-moves", choices=("limbs", "all"), default="limbs",
                        help="what the image level may move: limbs (default): the arms and legs, with the "
                             "root, spine, clavicles and neck held where the targets put them; all: every "
                             "joint the targets leave free, as in the paper")
    parser.add_argument("--trc-axes", choices=("auto", "y-up", "z-up"), default="auto",
                        help="axis convention of the TRC files: y-up as Pose2Sim and OpenSim write "
                             "them, z-up in the calibration's own world (as many mocap systems "
                             "export); auto (default) tells them apart by projecting the targets "
                             "into the cameras (y-up without --calibration)")
    parser.add_argument("--stack", type=Path, metavar="STACK.toml",
                        help="priority levels and their tasks (default: the package's default_stack.toml; "
                             "see the README, Priority stacks)")
    parser.add_argument("--read-ahead", choices=("process", "thread", "off"), default="process",
                        help="where the next frames' silhouettes are read and their support images built "
                             "while a frame is solved: process (default; a forked child process, a thread "
                             "where fork is not available, off Linux), thread, or off (on one core; ibik "
                             "batch's workers, a core each)")
    parser.add_argument("--no-read-ahead", dest="read_ahead", action="store_const", const="off",
                        help="the same as --read-ahead off")
    parser.add_argument("--overlay", action="store_true",
                        help="also write overlay videos, a residual plot and an HTML 3D replay")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--out", required=True, help="output folder")


def _job(arguments: argparse.Namespace) -> TrackJob:
    from ibik_pin.app.job import TrackJob
    from ibik_pin.solvers import DEFAULT_QP_SOLVER
    from ibik_pin.tracking.settings import TrackingSettings
    from ibik_pin.tracking.stack import Stack
    from ibik_pin.tracking.swivel_smoothing import parse_swivel_cutoff

    stack = Stack.from_toml(arguments.stack) if arguments.stack else None
    if arguments.qp_solver is not None and stack is not None and stack.qp_solver not in (None, arguments.qp_solver):
        raise InputError(f"--qp-solver {arguments.qp_solver} and --stack {arguments.stack}'s qp_solver = "
                         f"{stack.qp_solver!r}: give the backend once")
    return TrackJob(
        targets=arguments.targets,
        out=arguments.out,
        static=arguments.static,
        calibration=arguments.calibration,
        masks=arguments.masks,
        videos=arguments.videos,
        background=arguments.background,
        cameras=None if arguments.cameras is None else [name.strip() for name in arguments.cameras.split(",")],
        model=arguments.model,
        c3d_mapping=arguments.c3d_mapping,
        trial_lengths=arguments.trial_lengths,
        target_filter=arguments.target_filter,
        person=arguments.person,
        settings=TrackingSettings(method=arguments.method, qp_solver=arguments.qp_solver or DEFAULT_QP_SOLVER,
                                  iterations=arguments.iterations,
                                  step_tolerance=arguments.step_tolerance, image_stop=arguments.image_stop,
                                  use_image=not arguments.no_image, mask_filter_radius=arguments.mask_filter,
                                  criterion=arguments.criterion, swivel_search=arguments.swivel_search,
                                  image_moves=arguments.image_moves, read_ahead=arguments.read_ahead,
                                  swivel_cutoff_hz=parse_swivel_cutoff(arguments.swivel_cutoff), stack=stack),
        overlay=arguments.overlay,
        quiet=arguments.quiet,
        trc_axes=arguments.trc_axes,
        segmenter=arguments.segmenter,
        triangulated_limbs=arguments.triangulated_limbs,
        refit_cameras=None if arguments.refit_cameras is None
        else [name.strip() for name in arguments.refit_cameras.split(",")],
    )


def _add_calibrate_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("static", type=Path, help="TRC of the subject's static trial (Pose2Sim keypoint names)")
    parser.add_argument("--out", type=Path, required=True,
                        help="the subject's URDF to write (NAME.urdf; NAME.calibration.json is written beside it)")
    parser.add_argument("--model", type=Path, help="URDF of the human to start from (default: example-robot-data's)")
    parser.add_argument("--frames", metavar="FIRST:LAST",
                        help="TRC frame numbers of the static frames to fit, both included (default: all, "
                             "at most 10 spread over them)")


def _calibrate(arguments: argparse.Namespace) -> None:
    """`ibik calibrate`: fit the subject on the static trial, write its URDF and figures, print them."""
    from ibik_pin.app.calibrate import run_calibrate

    run = run_calibrate(arguments.static, arguments.out, arguments.model, arguments.frames)
    print(run.result.table())
    print(f"wrote {arguments.out} and {run.figures}")


def _convert_calibration(arguments: argparse.Namespace) -> None:
    """`ibik convert-calibration`: read any calibration format, write Pose2Sim's TOML."""
    from ibik_pin.io.calibration import read_calibration, write_calibration

    if arguments.out.exists():
        raise InputError(f"--out {arguments.out}: the file exists; give a new name (nothing was written)")
    cameras = read_calibration(arguments.calibration)
    write_calibration(arguments.out, cameras)
    print(f"wrote {arguments.out}: {len(cameras)} cameras ({', '.join(camera.name for camera in cameras)})")


class _OneLineParser(argparse.ArgumentParser):
    """argparse with its errors in the package's form: one line on stderr, exit code 2."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"ibik: error: {' '.join(message.split())} (ibik {self.prog.partition(' ')[2] or ''}"
                     f"{' ' if ' ' in self.prog else ''}--help lists the options)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _OneLineParser(prog="ibik", description="Image-constrained inverse kinematics "
                            "for markerless human motion capture")
    commands = parser.add_subparsers(dest="command", required=True)
    track = commands.add_parser("track", help="track a recorded sequence")
    _add_track_arguments(track)
    calibrate = commands.add_parser("calibrate", help="fit the model to a subject's static trial, write it as URDF")
    _add_calibrate_arguments(calibrate)
    # resolve: the batch replaces the track options that name one trial's files (batch.command).
    batch = commands.add_parser("batch", conflict_handler="resolve",
                                help="track every trial under a folder on Dask (pip install 'ibik_pin[batch]')")
    _add_track_arguments(batch)
    add_batch_arguments(batch)
    convert = commands.add_parser("convert-calibration",
                                  help="write a calibration (Qualisys .qca.txt, EasyMocap intri.yml + extri.yml, "
                                       "Anipose TOML) as Pose2Sim's calibration TOML")
    convert.add_argument("calibration", type=Path, help="the calibration file (or EasyMocap's folder)")
    convert.add_argument("--out", type=Path, required=True, help="the TOML to write (an existing file is refused)")
    demo = commands.add_parser("demo", help="track the bundled real motion, with and without image")
    demo.add_argument("--out", type=Path, default=Path("out/demo"), help="output folder")
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def _one_line_warning(
    message: Warning | str, category: type[Warning], filename: str, lineno: int, line: str | None = None
) -> str:
    return f"ibik: warning: {' '.join(str(message).split())}\n"


class Terminated(BaseException):
    """SIGTERM, raised where the program is so that every cleanup (the staging folder) runs."""


# Modules whose ctypes callbacks run Python (Numba's compiler and its cache, through llvmlite): an
# exception a signal handler raises there is swallowed or turned into a SystemError, and LLVM is left
# half-way; CI saw a segfault from SIGTERM while a kernel was compiled into a cold cache.
_UNINTERRUPTIBLE_MODULES = ("numba.", "llvmlite.")
_RETRY_SECONDS = 0.02
_CAN_RETRY = hasattr(signal, "setitimer") and hasattr(signal, "SIGALRM")
_pending_signal: list[type[BaseException]] = []  # the signal taken and not yet raised, at most one


def _inside_uninterruptible(frame: types.FrameType | None) -> bool:
    while frame is not None:
        if str(frame.f_globals.get("__name__", "")).startswith(_UNINTERRUPTIBLE_MODULES):
            return True
        frame = frame.f_back
    return False


def _raise_where_safe(signal_number: int, frame: types.FrameType | None) -> None:
    """SIGTERM as Terminated, SIGINT as KeyboardInterrupt, raised where the program is so that every
    cleanup (the staging folder) runs; inside Numba's compiler, retried by SIGALRM every 20 ms until
    the program is out of it."""
    if signal_number in (signal.SIGTERM, signal.SIGINT) and not _pending_signal:
        _pending_signal.append(Terminated if signal_number == signal.SIGTERM else KeyboardInterrupt)
    if not _pending_signal:
        return  # an alarm that is not ours to act on
    if _CAN_RETRY and _inside_uninterruptible(frame):
        signal.setitimer(signal.ITIMER_REAL, _RETRY_SECONDS)
        return
    raise _pending_signal.pop()()


@contextlib.contextmanager
def _signals_raised_where_safe() -> Iterator[None]:
    """Install _raise_where_safe for the run, and put back the handlers there were (where the
    platform has no alarm to retry with, Windows, the signals are raised at once)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handled = (signal.SIGTERM, signal.SIGINT, signal.SIGALRM) if _CAN_RETRY else (signal.SIGTERM, signal.SIGINT)
    previous = {number: signal.signal(number, _raise_where_safe) for number in handled}
    try:
        yield
    finally:
        if _CAN_RETRY:
            signal.setitimer(signal.ITIMER_REAL, 0)
        _pending_signal.clear()
        for number, handler in previous.items():
            signal.signal(number, handler)


def main(argv: list[str] | None = None) -> int:
    arguments = build_parser().parse_args(argv)
    warnings.formatwarning = _one_line_warning
    # numpy's "Mean of empty slice" and the like: the package checks its inputs and reports what a
    # user can act on; numpy's own words about an intermediate array are noise on the one line.
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    with _signals_raised_where_safe():
        return _run(arguments)


def _command_started() -> float | None:
    """The time.perf_counter() at which this process started, when it is the `ibik` command: its
    interpreter's start and imports (about 1.5 s of a run on the demo's videos) then count in
    report.json's end-to-end time. None when another program calls main, or where the system does
    not tell a process's start (Linux's /proc does)."""
    if Path(sys.argv[0]).stem != "ibik":
        return None
    try:
        after_name = Path("/proc/self/stat").read_text().rpartition(")")[2].split()
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - int(after_name[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return None
    return time.perf_counter() - age if 0.0 <= age < 3600.0 else None


def _run(arguments: argparse.Namespace) -> int:
    try:
        if arguments.command == "track":
            from ibik_pin.app.track import run_track

            report = run_track(_job(arguments), started=_command_started())
            if not arguments.quiet:
                lines = report.summary_lines()
                print(f"wrote {arguments.out}: {lines[0]}")
                print("\n".join(lines[1:]))
        elif arguments.command == "calibrate":
            _calibrate(arguments)
        elif arguments.command == "convert-calibration":
            _convert_calibration(arguments)
        elif arguments.command == "batch":
            from ibik_pin.app.batch.command import run_batch_command

            return run_batch_command(arguments, _job)
        else:
            from ibik_pin.app.demo import run_demo

            run_demo(arguments.out, quiet=arguments.quiet)
    except (IbikError, OSError) as error:
        message = " ".join(str(error).split())  # one line, whatever the message held
        print(f"ibik: error: {message}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, Terminated) as error:
        print(f"ibik: {'interrupted' if isinstance(error, KeyboardInterrupt) else 'terminated'}", file=sys.stderr)
        return 130 if isinstance(error, KeyboardInterrupt) else 143
    return 0

if __name__ == "__main__":
    sys.exit(main())
