"""Tests of the frame images prepared ahead (in a child process, a thread, or in turn): the same
views as prepared in turn, frames read in order and once, errors raised at their frame, nothing
left running after the loop."""

import functools
import multiprocessing
import os
import threading

import numpy as np
import pinocchio as pin
import pytest

from ibik_pin.exceptions import IbikError, InputError
from ibik_pin.readahead.frame_images import frame_images
from ibik_pin.readahead.frames_ahead import READ_AHEAD_MODES, FrameImagesAhead
from ibik_pin.synthetic.silhouettes import render_silhouettes
from ibik_pin.vision.medial_axis import medial_axis_pixels
from ibik_pin.vision.pinhole import look_at_camera
from ibik_pin.vision.support import support_from_mask
from tests.conftest import random_human_configuration

FRAMES = 5


@pytest.fixture(scope="module")
def rig(human):
    """Two 160 x 120 cameras and FRAMES frames of silhouettes of a seeded moving pose; the third
    frame's second view empty (the person left it)."""
    rng = np.random.default_rng(7)
    start = random_human_configuration(human, rng, spread=0.3)
    end = random_human_configuration(human, rng, spread=0.3)
    end[:7] = start[:7]
    start[:3] = end[:3] = 0.0
    up = np.array([0.0, 1.0, 0.0])
    cameras = [look_at_camera(name, (160, 120), 150.0, eye, np.zeros(3), up)
               for name, eye in (("front", np.array([4.0, 0.5, 0.0])), ("side", np.array([0.0, 0.5, 4.0])))]
    masks = [render_silhouettes(human, pin.interpolate(human.model, start, end, t), cameras)
             for t in np.linspace(0.0, 0.3, FRAMES)]
    masks[2][1] = np.zeros_like(masks[2][1])
    return cameras, masks


class Source:
    """A silhouette source that records which frames were read, and by which process and thread;
    its records come back from a child process (readahead.image_process.FrameRecords)."""

    def __init__(self, masks, failing_frame: int | None = None) -> None:
        self.masks, self.failing_frame = masks, failing_frame
        self.read: list[tuple[int, int, str]] = []  # frame, process id, thread name

    def __call__(self, frame: int):
        self.read.append((frame, os.getpid(), threading.current_thread().name))
        if frame == self.failing_frame:
            raise InputError(f"frame {frame}: the mask cannot be read")
        return self.masks[frame]

    def recorded_frames(self) -> int:
        return len(self.read)

    def records(self, start, stop):
        return self.read[start:stop]

    def add_records(self, start, records) -> None:
        self.read[start:start + len(records)] = records

    def read_elsewhere(self, frame: int) -> None:
        self.read.append((frame, -1, "elsewhere"))


def prepare(source, cameras, frame):
    return frame_images(source, cameras, [4.0, 4.0], [6.0, 6.0], frame)


def _children() -> list:
    return [child for child in multiprocessing.active_children() if child.name == "ibik-frame-images"]


@pytest.mark.parametrize("mode", READ_AHEAD_MODES)
def test_frames_prepared_ahead_are_those_prepared_in_turn_read_in_order_and_once(rig, mode):
    """Twelve frames (the rig's five in turn), more than the process reader's slots: each frame is
    checked while it is valid, as the tracker uses it, and the frame before it still is."""
    cameras, masks = rig
    frames = 12
    masks = [masks[frame % FRAMES] for frame in range(frames)]
    ahead_source, turn_source = Source(masks), Source(masks)

    def check(ahead, frame):
        in_turn = prepare(turn_source, cameras, frame)
        assert ahead.disabled == in_turn.disabled == (["side"] if frame % FRAMES == 2 else [])
        for view, reference in zip(ahead.views, in_turn.views, strict=True):
            assert view.camera is reference.camera
            assert view.support.enabled == reference.support.enabled
            assert view.support.held_values()[1:] == reference.support.held_values()[1:]  # the same window
            np.testing.assert_array_equal(view.support.held_values()[0], reference.support.held_values()[0])
        assert ahead.axis_views is not None and in_turn.axis_views is not None
        for axis, reference in zip(ahead.axis_views, in_turn.axis_views, strict=True):
            np.testing.assert_array_equal(axis.pixels, reference.pixels)
            assert axis.robust_scale_px == reference.robust_scale_px

    with FrameImagesAhead(lambda frame: prepare(ahead_source, cameras, frame), frames, mode, ahead_source) as images:
        previous = None
        for frame in range(frames):
            current = images.get(frame)
            check(current, frame)
            if previous is not None:
                check(previous, frame - 1)
            previous = current
        for view, reference in zip(current.views, prepare(turn_source, cameras, frames - 1).views, strict=True):
            np.testing.assert_array_equal(view.support.values, reference.support.values)  # the whole frame
    assert [frame for frame, _, _ in ahead_source.read] == list(range(frames))
    here = (os.getpid(), threading.current_thread().name)
    where = {frame: (pid, thread) == here for frame, pid, thread in ahead_source.read}
    # Frame 0 is prepared here by a process reader, before it forks.
    assert where == {frame: mode == "off" or (mode == "process" and frame == 0) for frame in range(frames)}
    assert not _children()


@pytest.mark.parametrize("mode", READ_AHEAD_MODES)
def test_an_error_is_raised_at_its_frame_and_the_loop_leaves_nothing_running(rig, mode):
    cameras, masks = rig
    source = Source(masks, failing_frame=2)
    got = []

    def track_frames():
        with FrameImagesAhead(lambda frame: prepare(source, cameras, frame), FRAMES, mode) as images:
            for frame in range(FRAMES):
                got.append(images.get(frame).disabled)

    with pytest.raises(InputError, match="frame 2: the mask cannot be read"):
        track_frames()
    assert got == [[], []]  # frames 0 and 1 came through
    if mode != "process":  # a child's reads stay in the child without records
        assert [frame for frame, _, _ in source.read] == [0, 1, 2, 3][:len(source.read)] and len(source.read) <= 4
    assert not [thread for thread in threading.enumerate() if thread.name.startswith("ibik-frame-images")]
    assert not _children()


def test_the_process_reader_ends_its_child_when_the_loop_stops_early(rig):
    cameras, masks = rig
    source = Source(masks)
    with FrameImagesAhead(lambda frame: prepare(source, cameras, frame), FRAMES, "process") as images:
        images.get(0)
        images.get(1)
        assert len(_children()) == 1
        with pytest.raises(RuntimeError, match="in order"):
            images.get(3)
    assert not _children()


def test_a_child_that_dies_is_one_clear_error(rig):
    cameras, masks = rig
    source = Source(masks)

    def dying(frame):
        if frame == 2:
            os._exit(3)
        return prepare(source, cameras, frame)

    with FrameImagesAhead(dying, FRAMES, "process") as images:
        images.get(0)
        images.get(1)
        with pytest.raises(IbikError, match=r"ended before frame 2 \(exit code 3\)"):
            images.get(2)


def _job(frame, images, payload):
    """A job reading the child's copy of the frame's images: its disabled views and its payload."""
    return frame, payload, os.getpid(), None if images is None else list(images.disabled)


def _offloaded_frames(rig, frames, job=_job, wait_s=0.02):
    """Run `frames` frames in process mode, each frame's job offloaded where the child is ahead (it
    is, with a pause per frame); returns the frames offloaded and every result by frame."""
    import time

    cameras, masks = rig
    source = Source([masks[frame % FRAMES] for frame in range(frames)])
    offloaded, results = [], {}
    with FrameImagesAhead(lambda frame: prepare(source, cameras, frame), frames, "process", job=job) as images:
        for frame in range(frames):
            images.get(frame)
            time.sleep(wait_s)  # the solve: the child gets ahead meanwhile
            if images.offload(frame, f"payload {frame}"):
                offloaded.append(frame)
            results.update(images.results())
        results.update(images.finish_jobs())
    return offloaded, results


def test_jobs_offloaded_to_the_child_run_there_on_their_frames_images_and_all_come_back(rig):
    frames = 12
    offloaded, results = _offloaded_frames(rig, frames)
    # The child gets two frames ahead (child_is_ahead) while the parent waits, which it cannot on
    # the last two frames: none follow.
    assert set(offloaded) <= set(range(frames - 2)) and len(offloaded) >= frames // 2
    assert sorted(results) == offloaded
    for frame in offloaded:
        done_frame, payload, pid, disabled = results[frame]
        assert (done_frame, payload) == (frame, f"payload {frame}")
        assert pid != os.getpid()
        assert disabled == (["side"] if frame % FRAMES == 2 else [])  # the rig's third frame, on its images
    assert not _children()


def test_the_child_gets_far_ahead_while_the_first_frame_is_solved_and_its_jobs_find_their_images(rig):
    """While the parent searches the first frame's pose the child fills every slot of the mapping
    (as many as fit its budget, up to MAX_SLOTS), not only the few the parent holds; the jobs sent
    while it is that far ahead still read their own frames' images."""
    import time

    from ibik_pin.readahead.image_process import MAX_SLOTS, MIN_SLOTS

    cameras, masks = rig
    frames = MAX_SLOTS + 8
    source = Source([masks[frame % FRAMES] for frame in range(frames)])
    prepared = multiprocessing.Value("i", 0)

    def counting(frame):
        with prepared.get_lock():
            prepared.value += 1
        return prepare(source, cameras, frame)

    offloaded, results = [], {}
    with FrameImagesAhead(counting, frames, "process", job=_job) as images:
        images.get(0)
        deadline = time.monotonic() + 20.0
        while prepared.value < MAX_SLOTS and time.monotonic() < deadline:  # the first frame's search
            time.sleep(0.01)
        time.sleep(0.1)
        ahead = prepared.value - 1  # frame 0 is prepared here
        for frame in range(frames):
            if frame:
                images.get(frame)
            if images.offload(frame, f"payload {frame}"):
                offloaded.append(frame)
            results.update(images.results())
        results.update(images.finish_jobs())
    # Every slot filled (small views: the budget holds MAX_SLOTS of them) and one more frame
    # prepared, waiting for a slot.
    assert ahead == MAX_SLOTS + 1 > MIN_SLOTS + 1
    assert len(offloaded) >= MAX_SLOTS and sorted(results) == offloaded
    for frame in offloaded:
        assert results[frame][:2] == (frame, f"payload {frame}")
        assert results[frame][3] == (["side"] if frame % FRAMES == 2 else [])
    assert not _children()


def test_a_child_behind_the_parent_gets_no_job(rig):
    """A child slower than the parent (four large views) would only fall further behind: the
    parent does the work itself."""
    import time

    cameras, masks = rig
    source = Source(masks)

    def slow(frame):
        time.sleep(0.03)
        return prepare(source, cameras, frame)

    with FrameImagesAhead(slow, FRAMES, "process", job=_job) as images:
        for frame in range(FRAMES):
            images.get(frame)
            assert not images.offload(frame, None)
        assert images.finish_jobs() == {}


def test_only_the_process_mode_offloads(rig):
    cameras, masks = rig
    source = Source(masks)
    for mode in ("thread", "off"):
        with FrameImagesAhead(lambda frame: prepare(source, cameras, frame), FRAMES, mode, job=_job) as images:
            for frame in range(FRAMES):
                images.get(frame)
                assert not images.offload(frame, None)
            assert images.results() == {} and images.finish_jobs() == {}


def _failing_job(frame, images, payload, failing=(3,)):
    if frame in failing:
        raise InputError(f"frame {frame}: the job failed")
    return frame


def _dying_job(frame, images, payload):
    if frame == 3:
        os._exit(5)
    return frame


def test_a_job_that_fails_or_kills_the_child_is_one_clear_error_and_nothing_is_left_running(rig):
    with pytest.raises(InputError, match="frame 3: the job failed"):
        _offloaded_frames(rig, 10, _failing_job)
    assert not _children()
    # The last job offloaded (frame 7 of 10) failing: its error is the one raised, after the frames.
    with pytest.raises(InputError, match="frame 7: the job failed"):
        _offloaded_frames(rig, 10, functools.partial(_failing_job, failing=(7,)))
    assert not _children()
    with pytest.raises(IbikError, match=r"the process preparing the images ended before .*\(exit code 5\)"):
        _offloaded_frames(rig, 10, _dying_job)
    assert not _children()


def _mode_in_a_daemon(results) -> None:
    ahead = FrameImagesAhead(lambda frame: None, 2, "process")
    results.put(ahead.mode)


def test_a_pool_worker_which_may_not_fork_reads_ahead_in_a_thread():
    results = multiprocessing.get_context("fork").Queue()
    worker = multiprocessing.get_context("fork").Process(target=_mode_in_a_daemon, args=(results,), daemon=True)
    worker.start()
    worker.join(30)
    assert results.get(timeout=5) == "thread"


def test_an_unknown_mode_is_refused():
    with pytest.raises(InputError, match="read-ahead mode: expected one of process, thread, off"):
        FrameImagesAhead(None, 1, "fork")


def test_the_shared_distance_transform_gives_the_support_and_medial_axis_computed_alone(human, rig):
    """frame_images computes a silhouette's inside distance once for both; also for a silhouette
    cut by the frame's edge, where the medial axis computes its own (it takes the edge for a border)."""
    cameras, masks = rig
    close = look_at_camera("close", (160, 120), 150.0, np.array([1.2, 0.4, 0.3]), np.zeros(3),
                           np.array([0.0, 1.0, 0.0]))
    cut = render_silhouettes(human, pin.neutral(human.model), [close])[0]
    assert cut[0].any() or cut[-1].any() or cut[:, 0].any() or cut[:, -1].any()
    for camera, mask in ((cameras[0], masks[0][0]), (cameras[1], masks[4][1]), (close, cut)):
        images = frame_images(lambda frame, mask=mask: [mask], [camera], [4.0], [6.0], 0)
        np.testing.assert_array_equal(images.views[0].support.values, support_from_mask(mask, 4.0).values)
        assert images.axis_views is not None
        np.testing.assert_array_equal(images.axis_views[0].pixels, medial_axis_pixels(mask))


def test_without_medial_axes_none_are_built_and_the_supports_are_those_computed_alone(rig):
    """Without a medial axis the inside distance is computed only up to the cap (half a pixel
    more): the supports are the same to the bit."""
    cameras, masks = rig
    for frame in range(FRAMES):
        images = frame_images(Source(masks), cameras, [4.0, 2.5], None, frame)
        assert images.axis_views is None and len(images.views) == 2
        for view, mask, cap in zip(images.views, masks[frame], (4.0, 2.5), strict=True):
            if mask.any():
                np.testing.assert_array_equal(view.support.values, support_from_mask(mask, cap).values)
        uncapped = frame_images(Source(masks), cameras, [None, 2.5], None, frame)  # a view without a cap
        if masks[frame][0].any():
            np.testing.assert_array_equal(uncapped.views[0].support.values,
                                          support_from_mask(masks[frame][0], None).values)


def test_supports_without_medial_axes_sent_by_the_child_give_the_whole_frame_computed_alone(rig):
    """Their inside distances, exact up to the cap only, travel with their limit: a read outside
    the window in the parent computes the same whole frame."""
    cameras, masks = rig
    source = Source(masks)
    windowed = 0
    with FrameImagesAhead(lambda frame: frame_images(source, cameras, [4.0, 2.5], None, frame), FRAMES,
                          "process") as images:
        for frame in range(FRAMES):
            for view, mask, cap in zip(images.get(frame).views, masks[frame], (4.0, 2.5), strict=True):
                if mask.any():
                    windowed += view.support.held_values()[0].shape != mask.shape
                    np.testing.assert_array_equal(view.support.values, support_from_mask(mask, cap).values)
    assert windowed >= FRAMES
    assert not _children()


def test_target_boxes_hold_every_target_seen_in_front_of_each_camera(rig):
    from ibik_pin.tracking.views import target_boxes

    cameras, _ = rig
    rng = np.random.default_rng(4)
    targets = rng.normal(0.0, 0.3, (6, 5, 3))
    targets[2] = np.nan  # a frame without targets
    targets[3, 1:] = np.nan  # a frame with one
    targets[4, 0] = [8.0, 0.5, 0.0]  # behind the front camera (at x = 4, looking at the origin)
    boxes = target_boxes(cameras, targets)
    assert boxes.shape == (6, 2, 4) and boxes.dtype == np.int64
    assert not boxes[2].any()
    for frame in (0, 1, 3, 4, 5):
        for index, camera in enumerate(cameras):
            points = targets[frame][np.isfinite(targets[frame]).all(axis=1)]
            projection = camera.project_with_jacobian(points)
            seen = projection.pixels[projection.depth > 0.0]
            top, bottom, left, right = boxes[frame, index]
            width, height = camera.size
            inside = ((seen[:, 0] >= 0) & (seen[:, 0] <= width - 1) & (seen[:, 1] >= 0) & (seen[:, 1] <= height - 1))
            pixels = seen[inside]
            assert np.all((pixels[:, 1] >= top) & (pixels[:, 1] < bottom))
            assert np.all((pixels[:, 0] >= left) & (pixels[:, 0] < right))
            assert 0 <= top <= bottom <= height and 0 <= left <= right <= width
    # The point behind the front camera does not stretch its box.
    front = target_boxes(cameras[:1], targets[4:5, 1:])
    assert np.array_equal(target_boxes(cameras[:1], targets[4:5])[0, 0], front[0, 0])


def test_frame_images_cover_the_target_boxes_with_the_whole_frames_values(rig):
    cameras, masks = rig
    boxes = np.zeros((FRAMES, 2, 4), dtype=np.int64)
    boxes[:, 0] = [2, 30, 3, 40]  # a corner of the front view, away from the body
    images = frame_images(Source(masks), cameras, [4.0, 4.0], None, 0, target_boxes=boxes)
    held, row, column = images.views[0].support.held_values()
    assert row <= 2 and column <= 3 and row + held.shape[0] >= 30 and column + held.shape[1] >= 40
    plain = frame_images(Source(masks), cameras, [4.0, 4.0], None, 0)
    np.testing.assert_array_equal(images.views[0].support.values, plain.views[0].support.values)


def test_a_parent_waiting_on_a_slower_child_prepares_frames_the_child_has_not_reached(rig):
    """A child slower than the parent (one large view on the paper's arm): while it would wait, the
    parent claims and prepares frames beyond the child's reach (its slots ahead), which the child then
    skips. Every frame is still the one prepared in turn, read once, in the process that claimed
    it; a claimed frame's job stays with the parent (the child has not its images); the silhouette
    figures of every frame end up in the parent's reader, none read again for the report."""
    import time

    from ibik_pin.app.video_inputs import SilhouetteQualityReader
    from ibik_pin.readahead.image_process import MAX_SLOTS

    cameras, masks = rig
    frames = 3 * MAX_SLOTS  # the child, once fast, gets past frames it has skipped: its jobs still find their images
    masks = [masks[frame % FRAMES] for frame in range(frames)]
    parent = os.getpid()
    # Per frame, how often it was read and by which process, shared with the child.
    read_count, reader_pid = multiprocessing.Array("i", frames), multiprocessing.Array("i", frames)

    def masks_of_frame(frame):
        read_count[frame] += 1
        reader_pid[frame] = os.getpid()
        if os.getpid() != parent and frame < MAX_SLOTS // 2:
            time.sleep(0.01)  # the child's first frames are slow ones; then it gets ahead
        return masks[frame]

    targets = np.zeros((frames, 1, 3))  # the body's origin, inside the silhouettes
    reader = SilhouetteQualityReader(masks_of_frame, cameras, targets)
    offloaded, results = [], {}
    with FrameImagesAhead(lambda frame: prepare(reader, cameras, frame), frames, "process", reader,
                          job=_job) as images:
        for frame in range(frames):
            ahead = images.get(frame)
            in_turn = prepare(masks.__getitem__, cameras, frame)
            for view, reference in zip(ahead.views, in_turn.views, strict=True):
                np.testing.assert_array_equal(view.support.held_values()[0], reference.support.held_values()[0])
            # The solve; one long one once the child is fast, which it spends getting far ahead.
            time.sleep(0.05 if frame == MAX_SLOTS else 0.002)
            if images.offload(frame, None):
                offloaded.append(frame)
            results.update(images.results())
        results.update(images.finish_jobs())
    claimed = [frame for frame in range(1, frames) if reader_pid[frame] == parent]
    assert claimed and min(claimed) > MAX_SLOTS  # beyond what the child may have started
    assert list(read_count) == [1] * frames  # each frame read once
    assert offloaded and not set(offloaded) & set(claimed)
    assert sorted(results) == offloaded
    for frame in offloaded:  # each job on its frame's images, also past frames the child skipped
        assert results[frame][3] == (["side"] if frame % FRAMES == 2 else [])
    in_turn = SilhouetteQualityReader(masks.__getitem__, cameras, targets)
    assert reader.quality("masks") == in_turn.quality("masks")
    assert list(read_count) == [1] * frames  # every frame's figures came with its images
    assert not _children()


def test_a_frame_the_parent_claimed_fails_at_its_own_frame(rig):
    """The parent prepares a frame it claims well before the frame is asked for; a failure there is
    raised when that frame is asked, as the child's are, after every frame before it."""
    import time

    from ibik_pin.readahead.image_process import MAX_SLOTS

    cameras, masks = rig
    frames = MAX_SLOTS + 8
    failing = MAX_SLOTS + 2  # the first frame the parent claims, waiting for frame 1
    parent = os.getpid()
    failed_in = multiprocessing.Value("i", 0)  # the process that read the failing frame

    def masks_of_frame(frame):
        if os.getpid() != parent and frame == 1:  # the child held up until the parent has claimed
            deadline = time.monotonic() + 10.0
            while failed_in.value == 0 and time.monotonic() < deadline:
                time.sleep(0.001)
        if frame == failing:
            failed_in.value = os.getpid()
            raise InputError(f"frame {frame}: the mask cannot be read")
        return masks[frame % FRAMES]

    got = []

    def track_frames():
        with FrameImagesAhead(lambda frame: prepare(masks_of_frame, cameras, frame), frames, "process") as images:
            for frame in range(frames):
                images.get(frame)
                got.append(frame)

    with pytest.raises(InputError, match=f"frame {failing}: the mask cannot be read"):
        track_frames()
    assert got == list(range(failing))
    assert failed_in.value == parent  # claimed: read here, long before its frame
    assert not _children()


def test_views_built_side_by_side_are_those_built_one_at_a_time_here_and_in_a_forked_child(rig):
    """frame_images(workers=2) (readahead.view_workers): every frame's views, windows and axes as
    with one worker, the empty view reported alike; the pool made here before the read-ahead forks
    its child, which then makes its own (threads do not survive a fork)."""
    from ibik_pin.readahead.view_workers import map_views

    cameras, masks = rig
    assert map_views(lambda item: (item, os.getpid()), [3, 1, 2], 2) == [(3, os.getpid()), (1, os.getpid()),
                                                                       (2, os.getpid())]
    source = Source(masks)

    def side_by_side(frame):
        return frame_images(source, cameras, [4.0, 4.0], [6.0, 6.0], frame, workers=2)

    with FrameImagesAhead(side_by_side, FRAMES, "process", source) as images:
        for frame in range(FRAMES):
            ahead, here, alone = images.get(frame), side_by_side(frame), prepare(Source(masks), cameras, frame)
            for built in (ahead, here):
                assert built.disabled == alone.disabled == (["side"] if frame == 2 else [])
                for view, reference in zip(built.views, alone.views, strict=True):
                    assert view.camera is reference.camera and view.support.enabled == reference.support.enabled
                    np.testing.assert_array_equal(view.support.values, reference.support.values)
                for axis, reference in zip(built.axis_views, alone.axis_views, strict=True):
                    np.testing.assert_array_equal(axis.pixels, reference.pixels)
    assert not _children()


def test_the_read_ahead_builds_large_views_on_threads_and_small_ones_in_turn():
    from ibik_pin.readahead.view_workers import LARGE_VIEW_PIXELS, read_ahead_workers, usable_cores

    assert read_ahead_workers([(640, 480)] * 4) == 1  # ready before the solve needs them
    assert read_ahead_workers([(1088, 1920)] * 4) == usable_cores()
    assert read_ahead_workers([(1088, 1920), (640, 480)]) == 1
    assert read_ahead_workers([]) == 1
    assert 640 * 480 < LARGE_VIEW_PIXELS <= 1280 * 800


def test_items_built_ahead_come_in_order_the_next_built_while_the_current_is_used():
    """readahead.view_workers.built_ahead: the values of building in turn, item by item; the next
    item's build runs while the caller holds the current one; an error comes with its item."""
    from ibik_pin.readahead.view_workers import built_ahead

    started = {item: threading.Event() for item in range(4)}

    def build(item: int) -> int:
        started[item].set()
        return item * item

    taken = []
    for value in built_ahead(build, range(4)):
        item = len(taken)
        if item < 3:  # the next one was started before this one is handed back, or soon after
            assert started[item + 1].wait(timeout=10.0)
        taken.append(value)
    assert taken == [0, 1, 4, 9]
    assert list(built_ahead(build, [])) == []

    def failing(item: int) -> int:
        if item == 2:
            raise InputError("item 2 is bad")
        return item

    values = built_ahead(failing, range(4))
    assert [next(values), next(values)] == [0, 1]
    with pytest.raises(InputError, match="item 2 is bad"):
        next(values)
