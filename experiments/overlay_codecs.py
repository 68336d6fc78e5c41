"""Overlay video codecs on real footage: the H.264 encode `ibik track --overlay` writes against
OpenCV's mp4v, the encode it replaced (which Chromium refuses).

One camera of the Pose2Sim demo (../shared/data: 100 frames at 60 fps, 1080 x 1920), with Pose2Sim's
own triangulated skeleton projected through the demo's calibration, is written both ways; prints
and writes (overlay_codecs.json) each file's size, encode time and codec as PyAV reads it back.

Usage: python experiments/overlay_codecs.py --out out/overlay_codecs [--data ../shared/data] [--camera cam01]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import av
import cv2

from ibik_pin.io.calibration import POSE2SIM_TRC_TO_WORLD, read_calibration
from ibik_pin.io.trc import read_trc
from ibik_pin.io.video import VideoReader
from ibik_pin.vision.camera import cameras_in_frame
from ibik_pin.viz.drawing import draw_skeleton
from ibik_pin.viz.overlay import write_overlay_video

SEGMENTS = [("RHip", "RKnee"), ("RKnee", "RAnkle"), ("LHip", "LKnee"), ("LKnee", "LAnkle"), ("LHip", "RHip"),
            ("Neck", "Head"), ("RShoulder", "RElbow"), ("RElbow", "RWrist"), ("LShoulder", "LElbow"),
            ("LElbow", "LWrist"), ("LShoulder", "RShoulder")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1].parent / "shared" / "data")
    parser.add_argument("--camera", default="cam01")
    args = parser.parse_args()
    demo = args.data / "pose2sim_demo"
    args.out.mkdir(parents=True, exist_ok=True)
    trc = read_trc(demo / "ref3d" / "S00_P00_T01_BalancingTrial_0-100_filt_butterworth.trc")
    cameras = cameras_in_frame(read_calibration(demo / "Calib_qualisys_converted.toml"), POSE2SIM_TRC_TO_WORLD)
    camera = next(c for c in cameras if c.name.replace("_", "") == args.camera)
    starts = trc.positions[:, [trc.marker_names.index(a) for a, _ in SEGMENTS]]
    ends = trc.positions[:, [trc.marker_names.index(b) for _, b in SEGMENTS]]
    skeletons = [(camera.project(s), camera.project(e)) for s, e in zip(starts, ends, strict=True)]
    with VideoReader(demo / "videos" / f"{args.camera}.mp4") as reader:
        frames = list(reader)
    fps = float(trc.data_rate)

    results = {}
    started = time.perf_counter()
    write_overlay_video(args.out / "overlay_h264.mp4", frames, skeletons, fps, frame_numbers=trc.frame_numbers)
    results["h264 (ibik_pin, PyAV libx264)"] = (args.out / "overlay_h264.mp4", time.perf_counter() - started)

    started = time.perf_counter()
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(args.out / "overlay_mp4v.mp4"), cv2.VideoWriter.fourcc(*"mp4v"), fps, (width, height))
    for frame, (start, end) in zip(frames, skeletons, strict=True):
        writer.write(draw_skeleton(frame, start, end))
    writer.release()
    results["mp4v (OpenCV, before)"] = (args.out / "overlay_mp4v.mp4", time.perf_counter() - started)

    table = {}
    for name, (path, seconds) in results.items():
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            codec, pixel_format = stream.codec_context.name, stream.codec_context.pix_fmt
        table[name] = {"bytes": path.stat().st_size, "encode_seconds": round(seconds, 2), "codec": codec,
                       "pixel_format": pixel_format, "frames": len(frames), "size": f"{width} x {height}"}
        print(f"{name:32s} {path.stat().st_size / 1e6:7.2f} MB  {seconds:6.2f} s  {codec} {pixel_format}")
    (args.out / "overlay_codecs.json").write_text(json.dumps(table, indent=2) + "\n")


if __name__ == "__main__":
    main()
