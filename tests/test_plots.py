"""Plots: the joint-angle panels are motion.mot's columns; left and right are told apart."""

import numpy as np
import pytest

from ibik_pin.viz.plots import JOINT_ANGLES, Panel, _side_and_part, joint_angle_panels, plot_panels


def test_each_angle_panel_draws_the_mot_columns_it_names_left_and_right():
    rng = np.random.default_rng(5)
    columns = {name: rng.normal(size=20) for _, left, right in JOINT_ANGLES for name in (left, right)}
    columns["pelvis_tx"] = rng.normal(size=20)
    panels = joint_angle_panels(columns)
    assert [panel.title for panel in panels] == [title for title, _, _ in JOINT_ANGLES]
    for panel, (title, left, right) in zip(panels, JOINT_ANGLES, strict=True):
        assert panel.ylabel == f"{title} [deg]"
        assert panel.series["left"] is columns[left] and panel.series["right"] is columns[right]


def test_angle_panels_skip_missing_joints_and_give_none_for_another_models_motion():
    columns = {"left_knee_Z": np.zeros(3), "right_knee_Z": np.ones(3)}
    assert [panel.title for panel in joint_angle_panels(columns)] == ["knee flexion"]
    assert joint_angle_panels({"pelvis_tx": np.zeros(3)}) == []


@pytest.mark.parametrize(("label", "side", "part"), [
    ("LWrist", "left", "Wrist"), ("RBigToe", "right", "BigToe"), ("left_knee_Z", "left", "knee_Z"),
    ("right", "right", ""), ("Hip", None, "Hip"), ("Neck", None, "Neck"), ("mean", None, "mean")])
def test_a_series_label_is_read_as_its_side_and_part(label, side, part):
    assert _side_and_part(label) == (side, part)


def test_left_and_right_of_a_part_share_its_colour_and_differ_in_line_style(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    times = np.linspace(0, 1, 10)
    drawn = {}
    original = Figure.savefig

    def keep_lines(figure, *args, **kwargs):
        for line in figure.axes[0].get_lines():
            drawn[line.get_label()] = (line.get_color(), line.get_linestyle())
        return original(figure, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep_lines)
    series = {"LWrist": times, "RWrist": times + 1, "LAnkle": times * 2, "RAnkle": times * 3, "Hip": times}
    plot_panels(tmp_path / "r.png", times, [Panel(series, "residual [mm]", "residuals")])
    assert (tmp_path / "r.png").stat().st_size > 0
    assert drawn["LWrist"][0] == drawn["RWrist"][0] and drawn["LWrist"][1] != drawn["RWrist"][1]
    assert drawn["LWrist"][0] != drawn["LAnkle"][0] != drawn["Hip"][0]
    assert drawn["LAnkle"][1] == "-" and drawn["RAnkle"][1] == "--"
