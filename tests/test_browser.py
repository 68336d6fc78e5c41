"""The replay page and an overlay video in a real headless Chromium (Debian's `chromium`).

Each page is opened from file:// with the probe script below appended; the script writes what it
saw into the DOM, which `chromium --headless --dump-dom` prints. Skipped, with the reason, where no
Chromium is installed (`apt-get install chromium`).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from ibik_pin.viz.overlay import write_overlay_video
from ibik_pin.viz.replay import write_html_replay

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (Debian: apt-get install chromium)")

# Flags of a headless run on a machine without network or GPU (each background service off).
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--autoplay-policy=no-user-gesture-required", "--allow-file-access-from-files"]
# Probe results are written into this element of the page.
RESULT_PATTERN = re.compile(r'<pre id="probe-result">(.*?)</pre>', re.S)
# Virtual time the page gets before the DOM is dumped [ms].
TIME_BUDGET_MS = "8000"

ERROR_RECORDER = """<script>
window.probeErrors = [];
window.addEventListener("error", function (event) { window.probeErrors.push(String(event.message)); });
var probeConsoleError = console.error;
console.error = function () { window.probeErrors.push(Array.prototype.join.call(arguments, " "));
                              probeConsoleError.apply(console, arguments); };
</script>"""


def run_page(path, tmp_path) -> dict:
    completed = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", f"--virtual-time-budget={TIME_BUDGET_MS}",
         "--dump-dom", path.as_uri()],
        capture_output=True, text=True, timeout=120, check=False,
    )
    found = RESULT_PATTERN.search(completed.stdout)
    assert found, f"no probe result in the page (exit {completed.returncode}): {completed.stderr[-2000:]}"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


def test_the_replay_runs_without_error_and_its_arrow_keys_work_after_clicking_play(tmp_path):
    rng = np.random.default_rng(3)
    positions = np.array([[0.0, 0.9, 0.0], [0.0, 1.4, 0.0], [0.0, 1.65, 0.0]]) + rng.normal(0, 0.01, (12, 3, 3))
    path = tmp_path / "replay.html"
    write_html_replay(path, ["Hip", "Neck", "Head"], [(0, 1), (1, 2)], positions, 10.0, title="probe")
    probe = """<pre id="probe-result"></pre><script>
    setTimeout(function () {
      var play = document.getElementById("play"), counter = document.getElementById("counter");
      play.focus();
      play.click();                               // what a mouse click does: focus, then click
      var focusAfterClick = document.activeElement.tagName;
      var before = counter.textContent;
      document.activeElement.dispatchEvent(new KeyboardEvent("keydown", {key: "ArrowRight", bubbles: true}));
      var after = counter.textContent;
      var follow = document.getElementById("follow"), reset = document.getElementById("reset");
      follow.focus(); follow.click(); var focusAfterCheckbox = document.activeElement.tagName;
      reset.focus(); reset.click(); var focusAfterReset = document.activeElement.tagName;
      document.getElementById("probe-result").textContent = JSON.stringify(
        {errors: window.probeErrors, focus: focusAfterClick, before: before, after: after,
         otherControls: [focusAfterCheckbox, focusAfterReset]});
    }, 500);
    </script>"""
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace("<head>", "<head>" + ERROR_RECORDER, 1).replace("</body>", probe + "</body>"),
                    encoding="utf-8")

    result = run_page(path, tmp_path)

    assert result["errors"] == []
    assert result["focus"] == "BODY"
    assert result["otherControls"] == ["BODY", "BODY"]
    frame_before = int(re.search(r"frame (\d+)", result["before"]).group(1))
    frame_after = int(re.search(r"frame (\d+)", result["after"]).group(1))
    assert frame_after == frame_before % 12 + 1 or frame_after == min(frame_before + 1, 12)


def test_an_overlay_video_plays_in_chromium(tmp_path):
    width, height = 320, 240
    frames = [np.full((height, width, 3), value, np.uint8) for value in range(40, 240, 10)]
    skeletons = [(np.array([[10.0, 10.0]]), np.array([[300.0, 200.0]]))] * len(frames)
    write_overlay_video(tmp_path / "overlay.mp4", frames, skeletons, 10.0)
    page = tmp_path / "video.html"
    page.write_text("""<!DOCTYPE html><html><head><meta charset="utf-8"></head><body>
    <video id="video" src="overlay.mp4" muted playsinline></video><pre id="probe-result"></pre><script>
    var video = document.getElementById("video"), out = document.getElementById("probe-result");
    function report(extra) {
      out.textContent = JSON.stringify(Object.assign({error: video.error ? video.error.code : null,
        width: video.videoWidth, height: video.videoHeight, duration: video.duration,
        time: video.currentTime}, extra));
    }
    video.addEventListener("error", function () { report({event: "error"}); });
    video.addEventListener("timeupdate", function () { if (video.currentTime > 0.5) { report({event: "played"}); } });
    video.play().catch(function (error) { report({event: "rejected: " + error.name}); });
    </script></body></html>""", encoding="utf-8")

    result = run_page(page, tmp_path)

    assert result["error"] is None  # MEDIA_ERR_SRC_NOT_SUPPORTED would be 4
    assert result["event"] == "played"
    assert (result["width"], result["height"]) == (width, height)
    assert result["duration"] == pytest.approx(2.0, abs=0.11)
