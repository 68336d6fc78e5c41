"""The Python API fed wrong types and values, as a careless script would: every public entry point
raises an InputError (an IbikError) that names the parameter, never an AttributeError, TypeError
or ValueError from deep inside, and writes nothing. Each case runs in a folder holding real inputs
(the demo's targets, calibration and masks) and an earlier output, which must stay byte for byte."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from ibik_pin.app.job import TrackJob
from ibik_pin.app.track import run_track
from ibik_pin.configuration import Configuration
from ibik_pin.exceptions import IbikError, InputError
from ibik_pin.human import load_human
from ibik_pin.io.asf import read_asf
from ibik_pin.io.bvh import read_bvh
from ibik_pin.io.calibration import read_calibration, write_calibration
from ibik_pin.io.export import write_model_bvh, write_model_mot, write_q_csv
from ibik_pin.io.keypoints import read_keypoints
from ibik_pin.io.masks import list_mask_files, read_mask
from ibik_pin.io.mot import read_mot
from ibik_pin.io.osim import write_osim_model
from ibik_pin.io.trc import read_trc, write_trc
from ibik_pin.io.video import VideoReader
from ibik_pin.limits import JointLimits
from ibik_pin.solvers import make_solver
from ibik_pin.subject.calibration import calibrate_subject
from ibik_pin.subject.scaling import scale_from_stature
from ibik_pin.subject.urdf import write_subject_urdf
from ibik_pin.tasks import FramePositionTask, PostureTask, View
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.vision.camera import select_cameras
from ibik_pin.vision.support import support_from_mask
from tests import test_hostile_inputs as hostile
from tests.test_hostile_inputs import Case, tree_digest

pristine, case = hostile.pristine, hostile.case  # the fixtures: real inputs and an earlier output


def _job(c: Case, **changes) -> TrackJob:
    given = {"targets": c.targets, "out": c.root / "api", "calibration": c.calibration, "masks": c.masks,
             "quiet": True, "settings": TrackingSettings(iterations=2)}
    given.update(changes)
    return TrackJob(**given)


def _first_mask(c: Case) -> Path:
    return sorted(c.masks.rglob("*.png"))[0]


def _camera(c: Case):
    return read_calibration(c.calibration)[0]


def _support(c: Case):
    camera = _camera(c)
    return support_from_mask(read_mask(_first_mask(c), tuple(camera.size)))


_BODY = None


def _body():
    global _BODY
    if _BODY is None:
        _BODY = load_human()
    return _BODY


def _tasks():
    body = _body()
    return FramePositionTask(body.model, "RWrist"), PostureTask(body.model)


def _solve(name: str, levels_of: Callable[[tuple], object]):
    body = _body()
    configuration = Configuration(body.model)
    return make_solver(name).solve(configuration, levels_of(_tasks()), iterations=1)


# (id, the call, a pattern the message must hold: the parameter it names)
CASES: list[tuple[str, Callable[[Case], object], str]] = [
    ("trackjob-settings-a-dict", lambda c: _job(c, settings={"iterations": 3}),
     r"^TrackJob\.settings: .*TrackingSettings"),
    ("trackjob-settings-none", lambda c: _job(c, settings=None), r"^TrackJob\.settings: "),
    ("trackjob-cameras-one-string", lambda c: _job(c, cameras="cam01"), r"^TrackJob\.cameras: .*'cam01'"),
    ("trackjob-refit-cameras-numbers", lambda c: _job(c, refit_cameras=[1, 2]), r"^TrackJob\.refit_cameras: "),
    ("trackjob-overlay-a-string", lambda c: _job(c, overlay="yes"), r"^TrackJob\.overlay: expected True or False"),
    ("trackjob-quiet-a-number", lambda c: _job(c, quiet=1), r"^TrackJob\.quiet: "),
    ("trackjob-trc-axes-none", lambda c: _job(c, trc_axes=None), r"^TrackJob\.trc_axes: "),
    ("trackjob-out-a-float", lambda c: _job(c, out=3.5), r"^TrackJob\.out: expected a path"),
    ("run-track-a-string", lambda c: run_track(str(c.targets)), r"^run_track: expected a TrackJob .*str"),
    ("run-track-a-dict", lambda c: run_track({"targets": c.targets, "out": c.root / "api"}), r"^run_track: .*dict"),
    ("read-mask-size-as-text", lambda c: read_mask(_first_mask(c), "640x480"), r"expected_size: .*'640x480'"),
    ("read-mask-size-one-side", lambda c: read_mask(_first_mask(c), (640,)), r"expected_size: "),
    ("read-mask-path-a-number", lambda c: read_mask(7), r"^path: expected a path"),
    ("list-mask-files-none", lambda c: list_mask_files(None), r"^folder: expected a path"),
    ("view-support-a-bare-mask", lambda c: View(_camera(c), read_mask(_first_mask(c))),
     r"^View\.support: .*support_from_mask.*ndarray"),
    ("view-camera-a-name", lambda c: View("cam01", _support(c)), r"^View\.camera: .*str"),
    ("qp-levels-not-nested", lambda c: _solve("qp", lambda tasks: list(tasks)), r"^levels\[0\]: .*nest them"),
    ("stack-levels-one-task", lambda c: _solve("stack", lambda tasks: tasks[0]), r"^levels: expected a list"),
    ("ik-level-holds-a-string", lambda c: _solve("ik", lambda tasks: [[tasks[0], "posture"]]),
     r"^levels\[0\]\[1\]: expected a task"),
    ("read-trc-a-number", lambda c: read_trc(123), r"^path: expected a path .*int"),
    ("read-trc-bytes", lambda c: read_trc(bytes(c.targets)), r"^path: expected a path .*bytes"),
    ("read-calibration-none", lambda c: read_calibration(None), r"^path: expected a path .*NoneType"),
    ("read-keypoints-a-list", lambda c: read_keypoints([c.targets]), r"^path: expected a path .*list"),
    ("read-bvh-empty-name", lambda c: read_bvh(""), r"^path: expected a path, found an empty name"),
    ("read-mot-a-path-in-a-tuple", lambda c: read_mot((c.targets,)), r"^path: expected a path .*tuple"),
    ("write-trc-a-dict", lambda c: write_trc(c.root / "written.trc", {"positions": []}),
     r"^data: expected a TrcData"),
    ("write-calibration-one-camera-bare", lambda c: write_calibration(c.root / "cal.toml", _camera(c)),
     r"^cameras: expected a list of PinholeCamera"),
    ("load-human-a-number", lambda c: load_human(3), r"^urdf_path: expected a path"),
    ("video-reader-a-number", lambda c: VideoReader(0), r"^path: expected a path .*int"),
    ("camera-project-text", lambda c: _camera(c).project("0 0 1"), r"^points_world: expected an array"),
    ("select-cameras-from-a-string", lambda c: select_cameras("cam01", ["cam01"]), r"^cameras: expected a list"),
    ("make-solver-limits-a-string", lambda c: make_solver("qp", limits="model"), r"^limits: expected a JointLimits"),
    ("configuration-of-a-name", lambda c: Configuration("human"), r"^model: expected a Pinocchio model"),
    ("configuration-q-as-text", lambda c: Configuration(_body().model, "0 0 0"), r"^q: expected numbers"),
    ("joint-limits-of-a-body", lambda c: JointLimits(_body()), r"^model: expected a Pinocchio model .*BodyModel"),
    ("calibrate-subject-body-a-path", lambda c: calibrate_subject(str(c.static), ["Hip"], [[[0.0, 1.0, 0.0]]]),
     r"^body: expected a BodyModel"),
    ("calibrate-subject-positions-text", lambda c: calibrate_subject(_body(), ["Hip"], "1 2 3"),
     r"^positions: expected numbers"),
    ("scale-from-stature-in-words", lambda c: scale_from_stature(_body(), "1.75 m"), r"^stature_m: expected a number"),
    ("write-q-csv-model-a-body", lambda c: write_q_csv(c.root / "q.csv", _body(), [0.0], [[0.0] * 45]),
     r"^model: expected a Pinocchio model .*BodyModel's \.model"),
    ("write-mot-q-as-text", lambda c: write_model_mot(c.root / "m.mot", _body().model, [0.0], "q"),
     r"^q: expected numbers"),
    ("write-bvh-body-a-model", lambda c: write_model_bvh(c.root / "m.bvh", _body().model, [[0.0] * 45], 0.01),
     r"^body: expected a BodyModel"),
    ("write-osim-body-a-path", lambda c: write_osim_model(c.root / "m.osim", str(c.static)),
     r"^body: expected a BodyModel"),
    ("write-subject-urdf-body-none", lambda c: write_subject_urdf(None, c.root / "s.urdf"),
     r"^body: expected a BodyModel"),
    ("read-asf-a-number", lambda c: read_asf(3), r"^path: expected a path .*int"),
]


@pytest.mark.parametrize(("call", "expected"), [pytest.param(call, expected, id=name)
                                                for name, call, expected in CASES])
def test_a_wrong_type_at_a_public_entry_point_is_an_input_error_naming_it(case, call, expected):
    before = tree_digest(case.root)

    with pytest.raises(IbikError) as raised:
        call(case)

    assert isinstance(raised.value, InputError), repr(raised.value)
    assert "\n" not in str(raised.value)
    assert re.search(expected, str(raised.value)), str(raised.value)
    assert tree_digest(case.root) == before


def test_the_cases_are_distinct():
    assert len(CASES) >= 40 and len({name for name, _, _ in CASES}) == len(CASES)


def test_the_right_types_still_pass_the_boundary(case):
    """The checks refuse the wrong types only: the same calls with the right ones go through."""
    job = _job(case, cameras=["cam01"], overlay=False, quiet=True)
    assert job.cameras == ["cam01"] and isinstance(job.targets, Path)
    camera = _camera(case)
    assert camera.project(np.zeros((1, 3)) + [0.0, 0.0, 1.0]).shape == (1, 2)
    result = _solve("qp", lambda tasks: [[tasks[0]], [tasks[1]]])
    assert np.all(np.isfinite(result.q))
