"""Tests of ibik_pin.tracking.stack: stack files read, checked, and refused with file, level and key."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from ibik_pin.cli import main
from ibik_pin.configuration import Configuration
from ibik_pin.io.trc import TrcData, write_trc
from ibik_pin.tracking.stack import Stack, StackError, TaskSpec

POSITION = '[[level.tasks]]\nkind = "position"\n'


def write_stack(folder: Path, text: str, name: str = "stack.toml") -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


def test_the_default_stack_is_today_s_four_levels(human):
    stack = Stack.default()
    assert [level.name for level in stack.levels] == ["lower-body targets", "upper-body targets", "image", "posture"]
    assert all(level.strict for level in stack.levels)
    lower = stack.levels[0].tasks[0]
    assert lower.kind == "position" and "LHeel" in (lower.keypoints or ()) and "Neck" not in (lower.keypoints or ())
    assert stack.levels[1].tasks == (TaskSpec("position"),)  # "present": every other target
    assert stack.levels[2].tasks == (TaskSpec("image"),)  # criterion and step from the settings
    assert stack.levels[3].tasks == (TaskSpec("posture", reference="neutral"),)
    stack.check_names(human.keypoints, ["cam1"])  # every keypoint it names is the human's


def test_every_key_of_every_task_kind_is_read(tmp_path):
    path = write_stack(tmp_path, """
        [[level]]
        name = "feet"
        [[level.tasks]]
        kind = "position"
        keypoints = ["LAnkle", "RAnkle"]
        weight = 2.0
        gain = 0.5
        [[level]]
        name = "soft"
        strict = false
        [[level.tasks]]
        kind = "image"
        criterion = "paper"
        views = ["cam2"]
        step = 0.02
        weight = 0.3
        [[level.tasks]]
        kind = "posture"
        reference = "previous"
        weight = 0.1
        [[level.tasks]]
        kind = "com"
        feet = ["LHeel", "RHeel"]
        weight = 4
    """)
    stack = Stack.from_toml(path)
    feet, soft = stack.levels
    assert feet.tasks == (TaskSpec("position", keypoints=("LAnkle", "RAnkle"), weight=2.0, gain=0.5),)
    assert not soft.strict
    assert soft.tasks == (TaskSpec("image", criterion="paper", views=("cam2",), step=0.02, weight=0.3),
                          TaskSpec("posture", reference="previous", weight=0.1),
                          TaskSpec("com", feet=("LHeel", "RHeel"), weight=4.0))
    assert stack.image == soft.tasks[0]
    assert str(path) in stack.source


BAD_STACKS = {
    "unknown task kind": ('[[level]]\nname = "a"\n' + POSITION
                          + '[[level]]\nname = "b"\n[[level.tasks]]\nkind = "force"\n',
                          r"level 2 \('b'\), task 1: key 'kind': unknown task kind 'force'; expected one of "),
    "keypoint in two levels": ('[[level]]\nname = "legs"\n' + POSITION + 'keypoints = ["LAnkle", "RAnkle"]\n'
                               '[[level]]\nname = "again"\n' + POSITION + 'keypoints = ["RAnkle"]\n',
                               r"level 2 \('again'\), task 1: key 'keypoints': keypoint 'RAnkle' is in level 1 too"),
    "negative weight": ('[[level]]\nname = "p"\n[[level.tasks]]\nkind = "posture"\nweight = -0.5\n',
                        r"level 1 \('p'\), task 1: key 'weight': expected a positive number, found -0.5"),
    "empty stack": ("# nothing\n", r"key 'level': the stack is empty"),
    "level without tasks": ('[[level]]\nname = "void"\nstrict = true\n',
                            r"level 1 \('void'\): key 'tasks': expected at least one"),
    "unknown key": ('[[level]]\nname = "x"\n' + POSITION + 'keypoint = ["Hip"]\n',
                    r"level 1 \('x'\), task 1: key 'keypoint': not a key of a position task"),
    "two image tasks": ('[[level]]\n[[level.tasks]]\nkind = "image"\n[[level]]\n[[level.tasks]]\nkind = "image"\n',
                        r"level 2 \('level 2'\), task 1: key 'kind': a second image task"),
    "two levels taking the rest": ('[[level]]\nname = "a"\n' + POSITION + '[[level]]\nname = "b"\n' + POSITION,
                                   r"level 2 \('b'\), task 1: key 'keypoints': \"present\" in level 1 too"),
    "a gain above one": ('[[level]]\n' + POSITION + 'gain = 2\n', r"task 1: key 'gain': expected a number in \(0, 1\]"),
    "an unknown criterion": ('[[level]]\n[[level.tasks]]\nkind = "image"\ncriterion = "mine"\n',
                             r"key 'criterion': expected one of paper, two-way, found 'mine'"),
    "the same level name twice": ('[[level]]\nname = "a"\n' + POSITION + '[[level]]\nname = "a"\n'
                                  '[[level.tasks]]\nkind = "posture"\n', r"level 2 \('a'\): key 'name'"),
    "a syntax error": ('[[level]\n', r"expected valid TOML, found a syntax error"),
}


@pytest.mark.parametrize("case", list(BAD_STACKS))
def test_a_bad_stack_file_is_refused_naming_the_file_level_and_key(tmp_path, case):
    text, message = BAD_STACKS[case]
    path = write_stack(tmp_path, text)
    with pytest.raises(StackError, match=message) as error:
        Stack.from_toml(path)
    assert f"stack file '{path}'" in str(error.value)


def test_a_missing_stack_file_is_refused():
    with pytest.raises(StackError, match=r"nowhere\.toml: cannot read this stack file"):
        Stack.from_toml("nowhere.toml")


def test_unknown_keypoints_and_cameras_are_refused_against_the_body_and_the_rig(tmp_path, human):
    stack = Stack.from_toml(write_stack(tmp_path, '[[level]]\nname = "arms"\n' + POSITION
                                        + 'keypoints = ["LWrist", "LTail"]\n[[level]]\n[[level.tasks]]\n'
                                          'kind = "image"\nviews = ["cam9"]\n'))
    with pytest.raises(StackError, match=r"level 1 \('arms'\), task 1: key 'keypoints': unknown keypoint 'LTail'"):
        stack.check_names(human.keypoints)
    with pytest.raises(StackError, match=r"level 2 \('level 2'\), task 1: key 'views': camera 'cam9' is not"):
        stack.check_names(["LWrist", "LTail"], ["cam1", "cam2"])


def small_trc(folder: Path, human) -> Path:
    """Two frames of the neutral human's keypoints, Y up, in metres."""
    names = ["Hip", "LHip", "RHip", "LAnkle", "RAnkle", "Neck", "Head", "LShoulder", "RShoulder", "LWrist", "RWrist"]
    configuration = Configuration(human.model)
    positions = configuration.frame_positions(human.frame_ids(names)) + np.array([0.0, 1.0, 0.0])
    path = folder / "targets.trc"
    write_trc(path, TrcData(marker_names=names, times=np.array([0.0, 0.01]), positions=np.stack([positions] * 2),
                            units="m", data_rate=100.0, frame_numbers=np.array([1, 2])))
    return path


@pytest.mark.parametrize(("text", "where"), [
    (BAD_STACKS["unknown task kind"][0], "level 2 ('b'), task 1: key 'kind'"),
    (BAD_STACKS["keypoint in two levels"][0], "level 2 ('again'), task 1: key 'keypoints'"),
    (BAD_STACKS["negative weight"][0], "level 1 ('p'), task 1: key 'weight'"),
    (BAD_STACKS["empty stack"][0], "key 'level'"),
    ('[[level]]\nname = "arms"\n' + POSITION + 'keypoints = ["LWrist", "LTail"]\n',
     "level 1 ('arms'), task 1: key 'keypoints': unknown keypoint 'LTail'"),
])
def test_ibik_track_refuses_a_bad_stack_with_exit_2_and_one_line(tmp_path, human, capsys, text, where):
    path = write_stack(tmp_path, text)
    out = tmp_path / "out"
    code = main(["track", "--targets", str(small_trc(tmp_path, human)), "--no-image", "--stack", str(path),
                 "--quiet", "--out", str(out)])
    error = capsys.readouterr().err
    assert code == 2
    assert error.count("\n") == 1 and error.startswith("ibik: error: ")
    assert f"stack file '{path}': {where}" in error
    assert not out.exists()



def test_ibik_track_reports_each_level_of_the_stack_it_was_given(tmp_path, human):
    import json

    path = write_stack(tmp_path, '[[level]]\nname = "legs"\n' + POSITION + 'keypoints = ["Hip", "LAnkle", "RAnkle"]\n'
                       '[[level]]\nname = "rest"\n' + POSITION + '[[level]]\nname = "prior"\n[[level.tasks]]\n'
                       'kind = "posture"\nreference = "previous"\n')
    out = tmp_path / "out"
    assert main(["track", "--targets", str(small_trc(tmp_path, human)), "--no-image", "--stack", str(path),
                 "--quiet", "--out", str(out)]) == 0
    levels = json.loads((out / "report.json").read_text())["solver_levels"]
    assert levels["stack"] == f"stack file '{path}'"
    assert levels["levels"] == ["legs", "rest", "prior"]
    for name in levels["levels"]:
        assert len(levels["status_per_frame"][name]) == 2
        assert len(levels["residual_per_frame"][name]) == len(levels["sacrificed_per_frame"][name]) == 2
    assert levels["mean_sacrificed"]["legs"] == 0.0
    assert levels["status_per_frame"]["legs"] == ["solved", "solved"]


def test_the_readme_s_example_stack_is_valid(human, tmp_path):
    from tests.paths import REPOSITORY

    readme = (REPOSITORY / "README.md").read_text()
    section = readme[readme.index("## Priority stacks"):]
    example = section[section.index("```toml") + len("```toml"):section.index("```\n\n")]
    stack = Stack.from_toml(write_stack(tmp_path, example))
    assert [level.name for level in stack.levels] == ["legs", "image", "arms and head", "posture"]
    stack.check_names(human.keypoints, ["cam1", "cam2"])
