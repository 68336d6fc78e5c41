"""Tests of ibik_pin.io.trc: reading Pose2Sim TRC files, writing them back, malformed files."""

import re
from pathlib import Path

import numpy as np
import pytest

import ibik_pin.io.files
from ibik_pin.exceptions import FileFormatError, IbikWarning, InputError
from ibik_pin.io.trc import TrcData, read_trc, write_trc
from tests.paths import SHARED_DATA

POSE2SIM_TRC_FILES = sorted((SHARED_DATA / "pose2sim_demo" / "ref3d").glob("*.trc"))
needs_pose2sim_files = pytest.mark.skipif(
    not POSE2SIM_TRC_FILES, reason="the shared Pose2Sim demo data is not beside the repository"
)

SMALL_TRC_HEADER = (
    "PathFileType\t4\t(X/Y/Z)\tsmall.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "50\t50\t{frames}\t2\t{units}\t50\t1\t{frames}\n"
    "Frame#\tTime\tA\t\t\tB\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
)


def write_pose2sim_excerpt(
    source: Path, destination: Path, blank_line: bool, frame_count: int = 10
) -> None:
    """Write the header and first frames of a Pose2Sim TRC, NumFrames set to match."""
    lines = source.read_text().splitlines()
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    values[keys.index("NumFrames")] = str(frame_count)
    rows = [line for line in lines[5:] if line.strip()][:frame_count]
    header = [lines[0], lines[1], "\t".join(values), lines[3], lines[4]]
    destination.write_text("\n".join(header + ([""] if blank_line else []) + rows) + "\n")


def small_trc(tmp_path: Path, rows: str, frames: int = 2, units: str = "mm") -> Path:
    path = tmp_path / "small.trc"
    path.write_text(SMALL_TRC_HEADER.format(frames=frames, units=units) + rows)
    return path


@needs_pose2sim_files
@pytest.mark.parametrize("source", POSE2SIM_TRC_FILES, ids=lambda path: path.name)
def test_pose2sim_excerpts_read_the_same_with_and_without_the_blank_line(source, tmp_path):
    write_pose2sim_excerpt(source, tmp_path / "with.trc", blank_line=True)
    write_pose2sim_excerpt(source, tmp_path / "without.trc", blank_line=False)

    with_blank = read_trc(tmp_path / "with.trc")
    without_blank = read_trc(tmp_path / "without.trc")

    first_row = next(line for line in source.read_text().splitlines()[5:] if line.strip()).split(
        "\t"
    )
    marker_count = len(with_blank.marker_names)
    assert with_blank.positions.shape == (10, marker_count, 3)
    assert with_blank.marker_names[:3] == ["RHip", "RKnee", "RAnkle"]
    assert with_blank.units == "m"
    assert with_blank.data_rate == 60.0
    np.testing.assert_array_equal(with_blank.frame_numbers, np.arange(1, 11))
    np.testing.assert_allclose(np.diff(with_blank.times), 1.0 / 60.0, atol=1e-6)
    np.testing.assert_array_equal(
        with_blank.positions[0].ravel(),
        [float(cell) for cell in first_row[2 : 2 + 3 * marker_count]],
    )
    np.testing.assert_array_equal(without_blank.positions, with_blank.positions)
    np.testing.assert_array_equal(without_blank.times, with_blank.times)


@needs_pose2sim_files
@pytest.mark.parametrize("source", POSE2SIM_TRC_FILES, ids=lambda path: path.name)
def test_writing_and_reading_a_pose2sim_excerpt_with_missing_markers_changes_nothing(
    source, tmp_path
):
    write_pose2sim_excerpt(source, tmp_path / "excerpt.trc", blank_line=False)
    original = read_trc(tmp_path / "excerpt.trc")
    original.positions[2, 1] = np.nan  # a marker missing at one frame
    original.positions[5:, -1] = np.nan  # the last marker lost from frame 5 on: rows end early

    write_trc(tmp_path / "written.trc", original)
    again = read_trc(tmp_path / "written.trc")

    assert again.marker_names == original.marker_names
    assert again.units == original.units
    assert again.data_rate == original.data_rate
    assert again.camera_rate == original.camera_rate
    np.testing.assert_array_equal(again.frame_numbers, original.frame_numbers)
    np.testing.assert_array_equal(again.times, original.times)
    np.testing.assert_array_equal(again.positions, original.positions)  # NaN where NaN


def test_written_file_has_the_opensim_layout(tmp_path):
    data = TrcData(
        marker_names=["A", "B"],
        times=[0.0, 0.02],
        positions=[[[1.0, 2.0, 3.0], [np.nan, np.nan, np.nan]], [[4.0, 5.0, 6.0], [7.0, 8.0, 9.5]]],
        units="mm",
        data_rate=50.0,
        frame_numbers=[1, 2],
    )
    write_trc(tmp_path / "out.trc", data)

    lines = (tmp_path / "out.trc").read_text().split("\n")
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\tout.trc"
    assert lines[1] == (
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames"
    )
    assert lines[2] == "50.0\t50.0\t2\t2\tmm\t50.0\t1\t2"
    assert lines[3] == "Frame#\tTime\tA\t\t\tB\t\t"
    assert lines[4] == "\t\tX1\tY1\tZ1\tX2\tY2\tZ2"
    assert lines[5] == ""
    assert lines[6] == "1\t0.0\t1.0\t2.0\t3.0\t\t\t"
    assert lines[7] == "2\t0.02\t4.0\t5.0\t6.0\t7.0\t8.0\t9.5"
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_windows_written_trc_reads_like_the_plain_one(tmp_path):
    """A byte-order mark, CRLF line ends and a Windows-1252 file name in the header, as Windows
    tools write them; a binary file is refused as such."""
    data = TrcData(marker_names=["A", "B"], times=[0.0, 0.02],
                   positions=[[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], [[7.0, 8.0, 9.0], [1.5, 2.5, 3.5]]],
                   units="mm", data_rate=50.0, frame_numbers=[1, 2])
    write_trc(tmp_path / "plain.trc", data)
    text = (tmp_path / "plain.trc").read_text().replace("plain.trc", "pr\u00e9cis.trc")
    (tmp_path / "windows.trc").write_bytes(b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode("utf-8"))
    (tmp_path / "western.trc").write_bytes(text.encode("cp1252"))
    for name in ("windows.trc", "western.trc"):
        read = read_trc(tmp_path / name)
        assert read.marker_names == ["A", "B"] and np.array_equal(read.positions, np.asarray(data.positions))
    (tmp_path / "binary.trc").write_bytes(b"PathFileType\x00\x01\x02")
    with pytest.raises(FileFormatError, match=r"binary\.trc: cannot read this TRC file: it is binary, not text"):
        read_trc(tmp_path / "binary.trc")


def test_empty_cells_and_rows_shorter_than_the_header_read_as_nan(tmp_path):
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\t\t\t\n2\t0.02\t4\t\t6\n")

    data = read_trc(path)

    expected = [[[1, 2, 3], [np.nan] * 3], [[4, np.nan, 6], [np.nan] * 3]]
    np.testing.assert_array_equal(data.positions, expected)
    assert data.marker_names == ["A", "B"]


def test_in_metres_scales_millimetres_and_leaves_the_original_unchanged(tmp_path):
    data = read_trc(small_trc(tmp_path, "1\t0.0\t1000\t-2\t3\t4\t5\t6\n2\t0.02\t1\t2\t3\n"))

    in_metres = data.in_metres()

    assert in_metres.units == "m"
    np.testing.assert_allclose(in_metres.positions[0, 0], [1.0, -0.002, 0.003], rtol=1e-12)
    assert np.isnan(in_metres.positions[1, 1]).all()
    assert data.units == "mm" and data.positions[0, 0, 0] == 1000.0


def test_rows_beyond_num_frames_are_kept_with_a_warning(tmp_path):
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\n2\t0.02\t1\t2\t3\n3\t0.04\t1\t2\t3\n", frames=2)

    with pytest.warns(IbikWarning, match="NumFrames is 2 but the file holds 3 data rows"):
        data = read_trc(path)

    assert data.positions.shape == (3, 2, 3)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            SMALL_TRC_HEADER.format(frames=1, units="mm").replace("PathFileType", "Path"),
            "line 1: expected 'PathFileType', got 'Path\\t4",
        ),
        (
            SMALL_TRC_HEADER.format(frames=1, units="mm").replace("\t2\tmm", "\t3\tmm") + "1\t0\n",
            "line 4: NumMarkers is 3 but the line names 2 markers",
        ),
        (
            SMALL_TRC_HEADER.format(frames=1, units="inch") + "1\t0\n",
            "line 3: Units: expected one of ['cm', 'm', 'mm'], got 'inch'",
        ),
        (
            SMALL_TRC_HEADER.format(frames="ten", units="mm"),
            "line 3: NumFrames: expected a non-negative integer, got 'ten'",
        ),
        (
            SMALL_TRC_HEADER.format(frames=1, units="mm") + "1\t0.0\t1\t2\t3\t4\tabc\t6\n",
            "line 6: B Y: expected a number, got 'abc'",
        ),
        (
            SMALL_TRC_HEADER.format(frames=1, units="mm") + "\n1\t\t1\t2\t3\n",
            "line 7: Time: expected a number, got ''",
        ),
        (
            SMALL_TRC_HEADER.format(frames=1, units="mm") + "1\t0.0\t1\t2\t3\t4\t5\t6\t7\n",
            "line 6: expected at most 8 columns (Frame#, Time, 2 markers x 3), got 9",
        ),
        (
            SMALL_TRC_HEADER.format(frames=3, units="mm") + "1\t0.0\t1\t2\t3\n",
            "NumFrames is 3 but the file holds 1 data rows",
        ),
        (
            SMALL_TRC_HEADER.format(frames=1, units="mm").replace("\t\tX1", "1\t0.0\t1"),
            "line 5: expected the axis labels 'X1 Y1 Z1 ...'",
        ),
        ("PathFileType\t4\n", "expected a 5-line TRC header, got 1 line(s)"),
    ],
    ids=[
        "no PathFileType",
        "NumMarkers disagrees with the names",
        "unknown units",
        "NumFrames not a number",
        "a cell is not a number",
        "a time is missing",
        "too many columns",
        "fewer rows than NumFrames",
        "no axis labels line",
        "header cut short",
    ],
)
def test_malformed_files_raise_file_format_errors_naming_the_problem(tmp_path, text, message):
    path = tmp_path / "bad.trc"
    path.write_text(text)

    with pytest.raises(FileFormatError, match=re.escape(message)) as error:
        read_trc(path)

    assert str(path) in str(error.value)


def test_a_missing_file_raises_a_file_format_error_naming_it(tmp_path):
    with pytest.raises(
        FileFormatError, match=re.escape(f"{tmp_path / 'none.trc'}: cannot read this TRC file")
    ):
        read_trc(tmp_path / "none.trc")


def test_a_failed_write_keeps_the_previous_file_and_leaves_no_temporary_file(tmp_path, monkeypatch):
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\t4\t5\t6\n2\t0.02\t1\t2\t3\t4\t5\t6\n")
    before = path.read_text()
    data = read_trc(path)

    def failing_replace(source, destination):
        raise OSError("disk full")

    monkeypatch.setattr(ibik_pin.io.files.os, "replace", failing_replace)
    with pytest.raises(InputError, match="cannot write: disk full"):
        write_trc(path, data)

    assert path.read_text() == before
    assert sorted(file.name for file in tmp_path.iterdir()) == ["small.trc"]


def test_positions_of_the_wrong_shape_raise_an_input_error():
    with pytest.raises(
        InputError, match=re.escape("positions: expected shape (2, 1, 3) for 2 times and 1 markers")
    ):
        TrcData(
            ["A"],
            times=[0.0, 0.1],
            positions=np.zeros((2, 2, 3)),
            units="m",
            data_rate=10.0,
            frame_numbers=[1, 2],
        )


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be"])
def test_a_utf16_export_reads_like_its_utf8_original(tmp_path, encoding):
    """Windows' "Unicode text" is UTF-16, with a byte-order mark or without; it is text, not binary."""
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\t4\t5\t6\n2\t0.02\t7\t8\t9\t1\t2\t3\n")
    (tmp_path / "wide.trc").write_bytes(path.read_text().replace("\n", "\r\n").encode(encoding))
    np.testing.assert_array_equal(read_trc(tmp_path / "wide.trc").positions, read_trc(path).positions)


def test_a_last_row_cut_short_by_an_interrupted_write_is_left_out_with_a_warning(tmp_path):
    # "-0" is the first two characters of "-0.5": a prefix, not a coordinate.
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\t4\t5\t6\n2\t0.02\t7\t8\t9\t1\t-0", frames=2)
    with pytest.warns(IbikWarning, match=r"line 7: the last row is cut short \(no line end, 7 of 8 cells\)"):
        data = read_trc(path)
    assert data.positions.shape == (1, 2, 3) and list(data.frame_numbers) == [1]


def test_a_complete_last_row_without_a_line_end_is_kept(tmp_path):
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\t4\t5\t6\n2\t0.02\t7\t8\t9\t1\t2\t3")
    assert read_trc(path).positions.shape == (2, 2, 3)


def test_a_frame_number_given_twice_is_refused_naming_both_lines(tmp_path):
    path = small_trc(tmp_path, "1\t0.0\t1\t2\t3\t4\t5\t6\n2\t0.02\t7\t8\t9\t1\t2\t3\n2\t0.04\t7\t8\t9\t1\t2\t3\n",
                     frames=3)
    with pytest.raises(FileFormatError, match=r"lines 7 and 8: expected each Frame# once, found 2 twice"):
        read_trc(path)


def test_marker_names_are_read_in_their_composed_unicode_form(tmp_path):
    decomposed = SMALL_TRC_HEADER.replace("\tA\t", "\tCre\u0300me\t").replace("\tB\t", "\tCr\u00e8me\t")
    (tmp_path / "accents.trc").write_text(decomposed.format(frames=1, units="mm") + "1\t0\t1\t2\t3\t4\t5\t6\n")
    assert read_trc(tmp_path / "accents.trc").marker_names == ["Cr\u00e8me", "Cr\u00e8me"]
