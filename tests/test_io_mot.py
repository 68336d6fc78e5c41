"""Tests of ibik_pin.io.mot: OpenSim storage files written and read back, malformed files."""

import re

import numpy as np
import pytest

from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError
from ibik_pin.io.mot import read_mot, write_mot

COLUMN_NAMES = ["pelvis_tilt", "pelvis_tx", "hip_flexion_r", "knee_angle_r"]


def random_motion(frame_count: int = 25):
    rng = np.random.default_rng(7)
    times = np.arange(frame_count) / 60.0
    values = rng.normal(scale=30.0, size=(frame_count, len(COLUMN_NAMES)))
    return times, values


@pytest.mark.parametrize("in_degrees", [True, False])
def test_writing_and_reading_a_motion_returns_the_same_values(tmp_path, in_degrees):
    times, values = random_motion()

    write_mot(
        tmp_path / "ik.mot", times, COLUMN_NAMES, values, in_degrees=in_degrees, name="Coordinates"
    )
    data = read_mot(tmp_path / "ik.mot")

    assert data.name == "Coordinates"
    assert data.column_names == COLUMN_NAMES
    assert data.in_degrees is in_degrees
    assert data.header == {
        "version": "1",
        "nRows": "25",
        "nColumns": "5",
        "inDegrees": "yes" if in_degrees else "no",
    }
    np.testing.assert_array_equal(data.times, times)
    np.testing.assert_array_equal(data.values, values)


def test_the_header_is_the_one_opensim_expects(tmp_path):
    times, values = random_motion(frame_count=3)

    write_mot(tmp_path / "ik.mot", times, COLUMN_NAMES, values)

    lines = (tmp_path / "ik.mot").read_text().split("\n")
    assert lines[:7] == [
        "motion",
        "version=1",
        "nRows=3",
        "nColumns=5",
        "inDegrees=yes",
        "endheader",
        "time\tpelvis_tilt\tpelvis_tx\thip_flexion_r\tknee_angle_r",
    ]
    assert [len(line.split("\t")) for line in lines[7:10]] == [5, 5, 5]
    assert lines[10:] == [""]


def test_an_opensim_file_with_free_text_in_its_header_is_read(tmp_path):
    path = tmp_path / "opensim.mot"
    path.write_text(
        "Coordinates\n"
        "version=1\n"
        "nRows=2\n"
        "nColumns=3\n"
        "inDegrees=yes\n"
        "\n"
        "Units are S.I. units (second, meters, Newtons, ...)\n"
        "If the header above contains a line with 'inDegrees', this indicates whether rotational "
        "values are in degrees (yes) or radians (no).\n"
        "\n"
        "endheader\n"
        "time\tpelvis_tilt\tknee_angle_r\n"
        "      0.00000000\t     -2.50000000\t     10.00000000\n"
        "      0.01000000\t     -2.25000000\t     12.50000000\n"
    )

    data = read_mot(path)

    assert data.column_names == ["pelvis_tilt", "knee_angle_r"]
    np.testing.assert_array_equal(data.times, [0.0, 0.01])
    np.testing.assert_array_equal(data.values, [[-2.5, 10.0], [-2.25, 12.5]])
    assert data.in_degrees


def test_a_file_without_in_degrees_is_in_radians_as_in_opensim(tmp_path):
    path = tmp_path / "radians.sto"
    path.write_text("states\nversion=1\nnRows=1\nnColumns=2\nendheader\ntime\tq\n0\t1.5\n")

    assert read_mot(path).in_degrees is False


def test_rows_beyond_n_rows_are_kept_with_a_warning(tmp_path):
    path = tmp_path / "long.mot"
    path.write_text(
        "m\nversion=1\nnRows=1\nnColumns=2\ninDegrees=no\nendheader\ntime\tq\n0\t1\n1\t2\n"
    )

    with pytest.warns(IbikWarning, match="nRows is 1 but the file holds 2 rows"):
        data = read_mot(path)

    np.testing.assert_array_equal(data.values, [[1.0], [2.0]])


HEADER = "m\nversion=1\nnRows={rows}\nnColumns={columns}\ninDegrees={degrees}\nendheader\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("m\nversion=1\nnRows=1\ntime\tq\n0\t1\n", "expected a line 'endheader', found none"),
        (
            HEADER.format(rows=1, columns=3, degrees="yes") + "time\tq\n0\t1\n",
            "nColumns is 3 but line 7 names 2 columns",
        ),
        (
            HEADER.format(rows=1, columns=2, degrees="maybe") + "time\tq\n0\t1\n",
            "inDegrees: expected 'yes' or 'no', got 'maybe'",
        ),
        (
            HEADER.format(rows=1, columns=2, degrees="yes") + "frame\tq\n0\t1\n",
            "line 7: expected the first column to be 'time', got ['frame']",
        ),
        (
            HEADER.format(rows=2, columns=2, degrees="yes") + "time\tq\n0\t1\n1\n",
            "line 9: expected 2 values, got 1",
        ),
        (
            HEADER.format(rows=1, columns=2, degrees="yes") + "time\tq\n0\tx\n",
            "line 8: expected numbers, got 'x'",
        ),
        (
            HEADER.format(rows=3, columns=2, degrees="yes") + "time\tq\n0\t1\n",
            "nRows is 3 but the file holds 1 rows",
        ),
        (
            HEADER.format(rows="many", columns=2, degrees="yes") + "time\tq\n0\t1\n",
            "line 3: nRows: expected a non-negative integer, got 'many'",
        ),
        (
            "m\nversion=1\nnRows=0\ninDegrees=yes\nendheader\ntime\tq\n",
            "expected a header line 'nColumns=...', found none",
        ),
        (
            HEADER.format(rows=0, columns=2, degrees="yes"),
            "line 7: expected the column names after 'endheader'",
        ),
    ],
    ids=[
        "no endheader",
        "nColumns disagrees with the names",
        "inDegrees neither yes nor no",
        "first column not time",
        "short row",
        "value not a number",
        "fewer rows than nRows",
        "nRows not a number",
        "no nColumns",
        "no column names",
    ],
)
def test_malformed_files_raise_file_format_errors_naming_the_problem(tmp_path, text, message):
    path = tmp_path / "bad.mot"
    path.write_text(text)

    with pytest.raises(FileFormatError, match=re.escape(message)) as error:
        read_mot(path)

    assert str(path) in str(error.value)


def test_values_that_do_not_match_the_column_names_raise_an_input_error(tmp_path):
    times, values = random_motion(frame_count=4)

    with pytest.raises(
        InputError,
        match=re.escape("values: expected shape (4, 3) for 4 times and 3 column names, got (4, 4)"),
    ):
        write_mot(tmp_path / "bad.mot", times, COLUMN_NAMES[:3], values)
    assert not list(tmp_path.iterdir())


def test_a_column_name_with_a_space_raises_an_input_error(tmp_path):
    with pytest.raises(InputError, match="column_names: expected non-empty names without spaces"):
        write_mot(tmp_path / "bad.mot", [0.0], ["knee angle"], [[1.0]])
