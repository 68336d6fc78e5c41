"""Tests of ibik_pin.report: the PNG plot, the overlay MP4 and the self-contained HTML replay."""

import json
import re
import shutil
import subprocess

import cv2
import matplotlib
import numpy as np
import pytest

from ibik_pin.exceptions import InputError
from ibik_pin.viz.overlay import write_overlay_video
from ibik_pin.viz.plots import plot_series
from ibik_pin.viz.replay import write_html_replay

VIDEO_SIZE = (160, 120)  # (width, height) [px]
FRAME_RATE = 10.0  # [Hz]
# mp4v is lossy: a colour read back from the video is within this of the one drawn (0-255).
VIDEO_COLOUR_TOLERANCE = 40
HTML_POSITION_TOLERANCE = 0.5e-4 + 1e-12  # [m]: rounded to 0.1 mm

KEYPOINTS = ["Hip", "Neck", "Head", "LHand", "RHand"]
SEGMENTS = [(0, 1), (1, 2), (1, 3), (1, 4)]


def video_frames(path):
    """Every frame of a video, (N, H, W, 3) BGR uint8."""
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    capture.release()
    return np.array(frames)


def diagonal_skeletons(count):
    """One segment from the top-left to the bottom-right corner per frame, [px]."""
    width, height = VIDEO_SIZE
    return [(np.array([[0.0, 0.0]]), np.array([[width - 1.0, height - 1.0]])) for _ in range(count)]


def square_mask():
    """A (H, W) silhouette: a 40 x 40 px square in the top-right corner, away from the diagonal."""
    width, height = VIDEO_SIZE
    mask = np.zeros((height, width), bool)
    mask[5:45, width - 45 : width - 5] = True
    return mask


def replay_data(path):
    """The JSON data block of a replay page."""
    text = path.read_text(encoding="utf-8")
    block = re.search(r'<script id="replay-data" type="application/json">(.*?)</script>', text, re.S)
    return json.loads(block.group(1))


def decoded_positions(skeleton, frame_count):
    """The (F, K, 3) positions [m] of one embedded skeleton, NaN for null."""
    values = np.array([np.nan if v is None else v for v in skeleton["positions"]], dtype=float)
    return values.reshape(frame_count, len(KEYPOINTS), 3) * 1e-4


@pytest.fixture
def walk(rng):
    """Positions (F, K, 3) [m] of a small skeleton walking along X, Y up."""
    frame_count = 10
    standing = np.array(
        [[0.0, 0.9, 0.0], [0.0, 1.4, 0.0], [0.0, 1.65, 0.0], [0.0, 0.9, -0.3], [0.0, 0.9, 0.3]]
    )
    steps = np.array([[0.08, 0.0, 0.0]]) * np.arange(frame_count)[:, np.newaxis]
    return standing + steps[:, np.newaxis, :] + rng.normal(0.0, 0.01, (frame_count, 5, 3))


def test_plot_is_a_png_of_800_by_450_pixels_and_leaves_the_matplotlib_backend_alone(tmp_path):
    backend = matplotlib.get_backend()
    times = np.arange(50) / FRAME_RATE
    path = tmp_path / "residuals.png"

    plot_series(
        path,
        times,
        {"left": np.sin(times), "right": np.where(times > 2.0, np.nan, np.cos(times))},
        ylabel="residual [mm]",
        title="end-effector residual",
    )

    image = cv2.imread(str(path))
    assert image.shape == (450, 800, 3)
    assert matplotlib.get_backend() == backend
    assert [p.name for p in tmp_path.iterdir()] == ["residuals.png"]


def test_plot_refuses_a_series_of_another_length_than_times(tmp_path):
    with pytest.raises(InputError, match=r"series\['knee'\]: expected shape \(5,\) like times"):
        plot_series(tmp_path / "x.png", np.arange(5.0), {"knee": np.zeros(4)}, "[deg]", "knee")


def test_overlay_video_holds_every_frame_with_the_mask_in_colour_and_the_skeleton(tmp_path):
    width, height = VIDEO_SIZE
    frame_count = 6
    frames = (np.full((height, width, 3), 90, np.uint8) for _ in range(frame_count))
    masks = (square_mask() for _ in range(frame_count))
    path = tmp_path / "overlay.mp4"

    written = write_overlay_video(path, frames, diagonal_skeletons(frame_count), FRAME_RATE, masks)

    video = video_frames(path).astype(int)
    assert written == frame_count
    assert video.shape == (frame_count, height, width, 3)
    on_line, in_mask, elsewhere = video[:, 60, 80], video[:, 25, width - 25], video[:, 100, 20]
    expected_mask = np.rint(0.6 * 90 + 0.4 * np.array([0, 0, 255]))  # overlay_mask, alpha 0.4
    np.testing.assert_allclose(on_line, np.tile([0, 255, 0], (6, 1)), atol=VIDEO_COLOUR_TOLERANCE)
    np.testing.assert_allclose(in_mask, np.tile(expected_mask, (6, 1)), atol=VIDEO_COLOUR_TOLERANCE)
    np.testing.assert_allclose(elsewhere, 90, atol=VIDEO_COLOUR_TOLERANCE)
    assert [p.name for p in tmp_path.iterdir()] == ["overlay.mp4"]


def test_overlay_video_without_images_draws_the_mask_grey_on_black(tmp_path):
    width, _ = VIDEO_SIZE
    path = tmp_path / "masks.mp4"

    write_overlay_video(path, None, diagonal_skeletons(3), FRAME_RATE, [square_mask()] * 3)

    video = video_frames(path).astype(int)
    np.testing.assert_allclose(video[:, 25, width - 25], 150, atol=VIDEO_COLOUR_TOLERANCE)
    np.testing.assert_allclose(video[:, 100, 20], 0, atol=VIDEO_COLOUR_TOLERANCE)


def test_overlay_video_accepts_grey_images(tmp_path):
    width, height = VIDEO_SIZE
    frames = [np.full((height, width), 200, np.uint8)] * 2

    assert write_overlay_video(tmp_path / "grey.mp4", frames, diagonal_skeletons(2), 25.0) == 2


def test_overlay_video_refuses_inputs_of_different_lengths_and_leaves_no_file(tmp_path):
    width, height = VIDEO_SIZE
    frames = [np.zeros((height, width, 3), np.uint8)] * 3

    with pytest.raises(InputError, match="skeletons: ended after 2 frames, but frames_bgr went on"):
        write_overlay_video(tmp_path / "short.mp4", frames, diagonal_skeletons(2), FRAME_RATE)
    assert list(tmp_path.iterdir()) == []


def test_overlay_video_refuses_a_frame_of_another_size(tmp_path):
    width, height = VIDEO_SIZE
    frames = [np.zeros((height, width, 3), np.uint8), np.zeros((height, width + 2, 3), np.uint8)]

    with pytest.raises(InputError, match=r"frame 1: expected 160 x 120 px like frame 0, got 162"):
        write_overlay_video(tmp_path / "sizes.mp4", frames, diagonal_skeletons(2), FRAME_RATE)
    assert list(tmp_path.iterdir()) == []


def test_overlay_video_into_a_missing_folder_raises_an_input_error_and_leaves_nothing(tmp_path):
    width, height = VIDEO_SIZE
    frames = [np.zeros((height, width, 3), np.uint8)]

    with pytest.raises(InputError, match=r"missing/x.mp4: cannot write: .*No such file or directory"):
        write_overlay_video(tmp_path / "missing" / "x.mp4", frames, diagonal_skeletons(1), 25.0)
    assert list(tmp_path.iterdir()) == []


def test_overlay_video_needs_images_or_masks(tmp_path):
    with pytest.raises(InputError, match="expected images, masks or both, got neither"):
        write_overlay_video(tmp_path / "x.mp4", None, diagonal_skeletons(1), FRAME_RATE)


def test_html_replay_is_one_file_that_needs_no_network(walk, tmp_path):
    path = tmp_path / "replay.html"

    write_html_replay(path, KEYPOINTS, SEGMENTS, walk, FRAME_RATE, title="walk")

    text = path.read_text(encoding="utf-8")
    assert "http://" not in text and "https://" not in text
    assert "<script src" not in text and "<link" not in text and "@import" not in text
    assert "<canvas" in text
    assert [p.name for p in tmp_path.iterdir()] == ["replay.html"]


def test_html_replay_embeds_positions_rounded_to_a_tenth_of_a_millimetre(walk, tmp_path):
    path = tmp_path / "replay.html"
    compare = walk + 0.02
    compare[3, 2] = np.nan

    write_html_replay(
        path, KEYPOINTS, SEGMENTS, walk, FRAME_RATE, title="walk",
        compare_positions=compare, compare_label="no images",
    )

    data = replay_data(path)
    frame_count = walk.shape[0]
    assert data["names"] == KEYPOINTS
    assert data["segments"] == [list(segment) for segment in SEGMENTS]
    assert data["frameCount"] == frame_count and data["frameRate"] == FRAME_RATE
    assert [skeleton["label"] for skeleton in data["skeletons"]] == ["tracked", "no images"]
    assert data["skeletons"][0]["color"] != data["skeletons"][1]["color"]
    embedded = decoded_positions(data["skeletons"][0], frame_count)
    embedded_compare = decoded_positions(data["skeletons"][1], frame_count)
    np.testing.assert_allclose(embedded, walk, atol=HTML_POSITION_TOLERANCE, rtol=0)
    assert np.isnan(embedded_compare[3, 2]).all()
    np.testing.assert_allclose(embedded_compare, compare, atol=HTML_POSITION_TOLERANCE, rtol=0)


def test_html_replay_turns_z_up_positions_y_up(walk, tmp_path):
    path = tmp_path / "replay.html"
    z_up = walk[..., [0, 2, 1]] * [1.0, -1.0, 1.0]  # (x, y, z) Y up -> (x, -z, y) Z up

    write_html_replay(path, KEYPOINTS, SEGMENTS, z_up, FRAME_RATE, title="walk", up_axis="z")

    embedded = decoded_positions(replay_data(path)["skeletons"][0], walk.shape[0])
    np.testing.assert_allclose(embedded, walk, atol=HTML_POSITION_TOLERANCE, rtol=0)


def test_html_replay_escapes_the_title_and_names_so_they_cannot_end_the_script(walk, tmp_path):
    path = tmp_path / "replay.html"
    names = [*KEYPOINTS[:-1], "</script><b>R"]

    write_html_replay(path, names, SEGMENTS, walk, FRAME_RATE, title="<i>walk</i> & run")

    text = path.read_text(encoding="utf-8")
    assert "<title>&lt;i&gt;walk&lt;/i&gt; &amp; run</title>" in text
    assert "</script><b>" not in text
    assert replay_data(path)["names"][-1] == "</script><b>R"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"segments": [(0, 5)]}, r"segments: expected pairs of keypoint indices in \[0, 4\]"),
        ({"up_axis": "x"}, "up_axis: expected 'y' or 'z', got 'x'"),
        ({"frame_rate": 0.0}, r"frame_rate: expected a positive number \[Hz\], got 0.0"),
        ({"compare_positions": np.zeros((3, 5, 3))}, "compare_positions: expected the shape"),
        ({"positions": np.full((2, 5, 3), np.nan)}, "expected at least one finite keypoint"),
        ({"keypoint_names": KEYPOINTS[:4]}, r"positions: expected shape \(F, 4, 3\)"),
    ],
)
def test_html_replay_names_the_argument_that_is_wrong(walk, tmp_path, arguments, message):
    given = {
        "keypoint_names": KEYPOINTS, "segments": SEGMENTS, "positions": walk,
        "frame_rate": FRAME_RATE, "title": "walk",
    }

    with pytest.raises(InputError, match=message):
        write_html_replay(tmp_path / "replay.html", **{**given, **arguments})
    assert list(tmp_path.iterdir()) == []


# The page's script run against a stub of the DOM and canvas: it draws, and every control and
# mouse or keyboard handler runs without a JavaScript error.
NODE_HARNESS = r"""
const fs = require("fs");
const html = fs.readFileSync(process.argv[1], "utf8");
const json = html.match(/<script id="replay-data" type="application\/json">([\s\S]*?)<\/script>/)[1];
const code = html.match(/<script>([\s\S]*?)<\/script>/)[1];
const calls = {};
const context = new Proxy({}, {
  get(target, name) {
    if (name in target) { return target[name]; }
    if (name === "measureText") { return () => ({ width: 20 }); }
    return () => { calls[name] = (calls[name] || 0) + 1; };
  },
  set(target, name, value) { target[name] = value; return true; },
});
const elements = {};
function element(id) {
  return {
    id, listeners: {}, style: {}, value: "1", checked: false, disabled: false,
    textContent: id === "replay-data" ? json : "",
    classList: { add() {}, remove() {} },
    addEventListener(type, listener) { this.listeners[type] = listener; },
    appendChild() {}, setPointerCapture() {}, blur() {}, getContext() { return context; },
    getBoundingClientRect() { return { left: 0, top: 0, width: 800, height: 600 }; },
  };
}
const document = {
  getElementById(id) { return elements[id] || (elements[id] = element(id)); },
  createElement() { return element(""); },
  createTextNode() { return {}; },
};
document.getElementById("canvas").parentElement = document.getElementById("view");
const windowListeners = {}, animationFrames = [];
const window = {
  devicePixelRatio: 2,
  addEventListener(type, listener) { windowListeners[type] = listener; },
  requestAnimationFrame(callback) { animationFrames.push(callback); },
};
new Function("document", "window", code)(document, window);

let stamp = 0;
function run(count) {
  for (let i = 0; i < count; i++) { stamp += 40; animationFrames.shift()(stamp); }
}
const event = (fields) => Object.assign({
  clientX: 0, clientY: 0, button: 0, shiftKey: false, pointerId: 1, deltaY: 0, deltaMode: 0,
  key: "", code: "", target: { tagName: "BODY" }, preventDefault() {},
}, fields);
const canvas = elements.canvas;
run(5);
canvas.listeners.pointerdown(event({ clientX: 100, clientY: 100 }));
canvas.listeners.pointermove(event({ clientX: 160, clientY: 80 }));
canvas.listeners.pointerup(event({}));
canvas.listeners.pointerdown(event({ clientX: 100, clientY: 100, shiftKey: true }));
canvas.listeners.pointermove(event({ clientX: 120, clientY: 130 }));
canvas.listeners.pointercancel(event({}));
canvas.listeners.wheel(event({ deltaY: -300 }));
canvas.listeners.pointermove(event({ clientX: 400, clientY: 300 }));
canvas.listeners.pointerleave(event({}));
windowListeners.keydown(event({ code: "Space", key: " " }));
windowListeners.keydown(event({ key: "ArrowRight" }));
elements.slider.value = "7";
elements.slider.listeners.input();
elements.speed.value = "2";
elements.speed.listeners.change();
elements.follow.checked = true;
elements.follow.listeners.change();
elements.names.checked = true;
elements.names.listeners.change();
canvas.listeners.dblclick();
elements.reset.listeners.click();
elements.play.listeners.click();
run(5);
console.log(JSON.stringify({ counter: elements.counter.textContent, calls }));
"""


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_html_replay_script_draws_and_handles_every_control_without_error(walk, tmp_path):
    path = tmp_path / "replay.html"
    write_html_replay(
        path, KEYPOINTS, SEGMENTS, walk, FRAME_RATE, title="walk", compare_positions=walk + 0.01
    )

    completed = subprocess.run(
        ["node", "-e", NODE_HARNESS, str(path)], capture_output=True, text=True, timeout=30
    )

    assert completed.returncode == 0, completed.stderr
    result = json.loads(completed.stdout)
    assert re.fullmatch(r"frame \d+ / 10 \u00b7 \d+\.\d{3} s", result["counter"])
    assert result["calls"]["stroke"] > 0 and result["calls"]["arc"] > 0
    assert result["calls"]["fillText"] >= len(KEYPOINTS)  # names shown


def test_overlay_video_is_h264_yuv420p_that_decodes_to_every_frame(tmp_path):
    import av

    width, height = 161, 121  # odd: yuv420p needs even sizes, the writer pads one black column and row
    frames = [np.full((height, width, 3), 90, np.uint8)] * 4
    path = tmp_path / "overlay.mp4"

    write_overlay_video(path, frames, diagonal_skeletons(4), FRAME_RATE, frame_numbers=[7, 8, 9, 10])

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        assert stream.codec_context.name == "h264"
        assert stream.codec_context.pix_fmt == "yuv420p"
        assert (stream.codec_context.width, stream.codec_context.height) == (162, 122)
        decoded = [frame.to_ndarray(format="bgr24") for frame in container.decode(stream)]
    assert len(decoded) == 4
    assert float(stream.average_rate) == pytest.approx(FRAME_RATE)
    np.testing.assert_allclose(decoded[0][100, 20].astype(int), 90, atol=VIDEO_COLOUR_TOLERANCE)


def test_overlay_video_shows_the_frame_number_and_legend_in_the_top_left_corner(tmp_path):
    width, height = 320, 240
    frames = [np.full((height, width, 3), 90, np.uint8)] * 2
    path = tmp_path / "overlay.mp4"
    no_segment = [(np.empty((0, 2)), np.empty((0, 2)))] * 2

    write_overlay_video(path, frames, no_segment, FRAME_RATE, masks=[np.zeros((height, width), bool)] * 2)

    video = video_frames(path).astype(int)
    corner, rest = video[:, :40, :120], video[:, 120:, 160:]
    assert (corner.max(axis=-1) > 200).mean() > 0.02  # white caption text and coloured legend lines
    assert (corner.max(axis=-1) < 40).mean() > 0.3  # on dark boxes
    np.testing.assert_allclose(rest, 90, atol=VIDEO_COLOUR_TOLERANCE)
