"""Why IBIK's elbows can end worse than PIK's: each elbow per frame, decomposed, and what moved it.

On sweep conditions whose files a sweep run kept (``sweep.py --keep FOLDER``), runs PIK and IBIK
(2 views) as the sweep does (``ibik track``; the trial-refined statics the sweep wrote) and, per
frame and elbow:

- the error against the truth, split on the limb's circle as docs/sweep.md does: the distance from
  the shoulder-wrist line (estimated vs true: the lengths), the swivel about that line [deg] and its
  chord [mm], the position along the line;
- where the elbow was after the frame's targets-only steps, whether the swivel search hinted it
  (and how far), and where the image steps left it: which stage moved it away from the truth.

Usage:
    python experiments/elbow_diagnosis.py --keep /tmp/h4_inputs --conditions 8 22 36
    python experiments/elbow_diagnosis.py --keep /tmp/h4_inputs --conditions 22 --set swivel_search=false
"""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path

import numpy as np
from realdata.runner import parse_settings
from sweepkit.conditions import draw_condition, load_condition
from sweepkit.runs import run_condition_variant

from ibik_pin.tracking import tracker as tracker_module
from ibik_pin.tracking.arm_support import arm_overlap
from ibik_pin.tracking.swivel import SwivelSearch, _even, limb_circles, outside_counts, trunk_distance

ELBOWS = {"LElbow": ("LShoulder", "LWrist"), "RElbow": ("RShoulder", "RWrist")}
#: Swivels at which the criterion is read on each elbow's circle per frame (--profiles).
PROFILE_SAMPLES = 72
#: Caps [m] of an arm's own support tried in the profiles: the overlap of the arm's samples read with
#: the support clipped at this depth (the support's own cap is tracking.views.LIMB_HALF_WIDTH).
ARM_CAPS = (0.01, 0.02, 0.03)


def swivel_profile(tracker, configuration) -> dict[str, np.ndarray]:
    """The swivel search's criterion around both elbows' circles at this configuration (the search's
    own circles: sample 0 is where the elbow is): the circles' centres, radii and unit vectors
    (E, 3), the summed criterion (E, A), whether each sample lies inside the trunk and how many of
    the arm's points fall outside the silhouettes (E, A); each term's weighted values (T, E, A) and
    the arm's own overlap (tracking.arm_support) at each of ARM_CAPS (E, A)."""
    search = tracker.swivel
    ids = np.array([search._limb_frame_ids(name) for name in ELBOWS])
    roots, middles, ends = configuration.frame_positions(ids.reshape(-1)).reshape(-1, 3, 3).transpose(1, 0, 2)
    circle = limb_circles(roots, middles, ends)
    points = circle.at(_even(PROFILE_SAMPLES))
    weighted, _ = search._weighted(search._term_poses(configuration), ids[:, 1], points)
    trunk = configuration.frame_positions(search._trunk_ids)
    return {"terms": weighted, "trunk_points": trunk, "centre": circle.centre, "radius": circle.radius,
            "capped": {cap: arm_overlap(tracker.image_task, roots, points, ends, cap) for cap in ARM_CAPS},
            "first": circle.first, "second": circle.second, "values": weighted.sum(axis=0),
            "trunk": search._inside_trunk(configuration, np.ones(2, bool), points),
            "outside": outside_counts(search.inside_silhouettes, roots, points, ends)}


class StageRecorder:
    """Records each frame's elbows after the targets-only steps and the swivel search's hints, by
    wrapping Tracker._swivel_hints (called once per frame solve, after those steps)."""

    def __init__(self, profiles: bool = False) -> None:
        self.profiles = profiles
        self.frames: list[dict] = []
        self._original = tracker_module.Tracker._swivel_hints

    def __enter__(self) -> StageRecorder:
        recorder, original = self, self._original

        def recording(tracker, configuration, free, frame):
            ids = tracker.body.frame_ids(list(ELBOWS))
            before = configuration.frame_positions(ids).copy()
            hints = tracker.swivel.hints(configuration, free)
            recorder.frames.append({"before": before, "hints": {k: v.copy() for k, v in hints.items()}})
            if recorder.profiles:
                recorder.frames[-1]["profile"] = swivel_profile(tracker, configuration)
            return original(tracker, configuration, free, frame)

        tracker_module.Tracker._swivel_hints = recording
        return self

    def __exit__(self, *exc) -> None:
        tracker_module.Tracker._swivel_hints = self._original


def _point(data, names: list[str], name: str) -> np.ndarray:
    return data[:, names.index(name)]


def _wrapped_deg(angles: np.ndarray) -> np.ndarray:
    """Angles [rad] wrapped to (-180, 180] deg."""
    return np.degrees((np.asarray(angles) + np.pi) % (2.0 * np.pi) - np.pi)


def profile_figures(profiles: list[dict], limb: int, true_elbow: np.ndarray, elbow: np.ndarray,
                    hints: list[np.ndarray | None]) -> dict[str, np.ndarray]:
    """Per frame, on the search's circle of elbow `limb`: where the criterion's best sample (outside the
    trunk) lies against the true swivel, where the final elbow and the hint lie [deg, signed]; how much
    lower the criterion is at the true swivel than at its best, in parts of its range over the circle
    (0: the truth is the peak); how wide the near-best region is (within 5 % of the range) [deg]; the
    best sample more than 30 deg from the first peak, its angle from the truth and its deficit."""
    rows: dict[str, list[float]] = {key: [] for key in (
        "best_deg", "final_deg", "hint_deg", "truth_deficit", "flat_deg", "second_deg", "second_deficit",
        "true_angle_deg", "final_angle_deg", "overlap_deg", "axis_deg", "trunk_nearer",
        *(f"capped_{cap * 1e3:.0f}_deg" for cap in ARM_CAPS))}
    for frame, profile in enumerate(profiles):
        centre, first, second = (profile[key][limb] for key in ("centre", "first", "second"))

        def angle(point, centre=centre, first=first, second=second):
            offset = point - centre
            return float(np.arctan2(offset @ second, offset @ first))

        values = np.where(profile["trunk"][limb], np.nan, profile["values"][limb])
        count = values.size
        grid = 2.0 * np.pi * np.arange(count) / count
        best = int(np.nanargmax(values))
        spread = max(float(np.nanmax(values) - np.nanmin(values)), 1e-12)
        truth = angle(true_elbow[frame])
        position = (truth % (2.0 * np.pi)) / (2.0 * np.pi) * count
        low, weight = int(np.floor(position)) % count, position - np.floor(position)
        at_truth = (1.0 - weight) * values[low] + weight * values[(low + 1) % count]
        deficit = (values[best] - at_truth) / spread
        near = np.abs(_wrapped_deg(grid - grid[best])) <= 30.0
        others = np.where(near, np.nan, values)
        second_best = int(np.nanargmax(others)) if np.isfinite(others).any() else best
        rows["best_deg"].append(float(_wrapped_deg(grid[best] - truth)))
        rows["final_deg"].append(float(_wrapped_deg(angle(elbow[frame]) - truth)))
        rows["hint_deg"].append(np.nan if hints[frame] is None else float(_wrapped_deg(angle(hints[frame]) - truth)))
        rows["truth_deficit"].append(float(deficit) if np.isfinite(deficit) else 1.0)
        rows["flat_deg"].append(float(np.sum(values >= values[best] - 0.05 * spread) * 360.0 / count))
        rows["second_deg"].append(float(_wrapped_deg(grid[second_best] - truth)))
        rows["second_deficit"].append(float((values[best] - values[second_best]) / spread))
        rows["true_angle_deg"].append(float(np.degrees(truth)))
        for index, key in enumerate(("overlap_deg", "axis_deg")):  # each term's own best swivel
            term = profile["terms"][min(index, len(profile["terms"]) - 1), limb]
            term = np.where(profile["trunk"][limb], np.nan, term)
            rows[key].append(float(_wrapped_deg(grid[int(np.nanargmax(term))] - truth)))
        for cap, capped in profile["capped"].items():  # the arm's overlap capped, plus the axis term
            total = np.where(profile["trunk"][limb], np.nan, capped[limb] + profile["terms"][-1, limb])
            rows[f"capped_{cap * 1e3:.0f}_deg"].append(float(_wrapped_deg(grid[int(np.nanargmax(total))] - truth)))
        centre_point = centre + (profile["radius"][limb] * (np.cos(grid[best]) * first + np.sin(grid[best]) * second))
        distances, _ = trunk_distance(np.stack([centre_point, true_elbow[frame]]), *profile["trunk_points"])
        rows["trunk_nearer"].append(float(distances[0] - distances[1]))
        rows["final_angle_deg"].append(float(np.degrees(angle(elbow[frame]))))
    return {key: np.array(value) for key, value in rows.items()}


def decompose(shoulder, elbow, wrist, true_shoulder, true_elbow, true_wrist) -> dict[str, np.ndarray]:
    """Per frame (F, 3 each): total error, distance from the line (estimated minus true), swivel
    error [deg] and its chord on the true circle [m], along-the-line offset [m], the true radius."""
    def frame_of(start, middle, end):
        axis = end - start
        axis = axis / np.linalg.norm(axis, axis=1, keepdims=True)
        along = np.einsum("fi,fi->f", middle - start, axis)
        radial = middle - start - along[:, None] * axis
        return axis, along, radial

    axis, along, radial = frame_of(shoulder, elbow, wrist)
    _, true_along, true_radial = frame_of(true_shoulder, true_elbow, true_wrist)
    radius, true_radius = np.linalg.norm(radial, axis=1), np.linalg.norm(true_radial, axis=1)
    # The true radial direction seen about the estimated line (the two lines are nearly parallel).
    projected = true_radial - np.einsum("fi,fi->f", true_radial, axis)[:, None] * axis
    cosine = np.einsum("fi,fi->f", radial, projected) / np.maximum(radius * np.linalg.norm(projected, axis=1), 1e-12)
    swivel = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
    return {"total": np.linalg.norm(elbow - true_elbow, axis=1), "radius_error": radius - true_radius,
            "swivel_deg": swivel, "chord": 2.0 * true_radius * np.sin(np.radians(swivel) / 2.0),
            "along_error": along - true_along, "true_radius": true_radius, "radius": radius}


def diagnose(inputs, kind: str, overrides: dict, profiles: bool = False, target_filter: str = "auto") -> dict:
    """PIK and IBIK 2v on one condition; per elbow the decomposition of both and IBIK's stages."""
    folder = inputs.folder
    suffix = "" if target_filter == "off" else f"_{target_filter}"  # sweepkit.lengths' names
    refined = folder / f"static_images2v_{kind}{suffix}.trc"
    reach = folder / f"static_reach{suffix}.trc"
    pik = run_condition_variant(inputs, "pik", kind, overrides, reach if reach.exists() else None, target_filter)
    with StageRecorder(profiles) as recorder:
        ibik = run_condition_variant(inputs, "ibik2v", kind, overrides, refined if refined.exists() else None,
                                     target_filter)
    frames = inputs.truth.shape[0]
    stages = recorder.frames[-frames:]
    truth_names = inputs.truth_names
    out: dict = {"index": inputs.condition.index, "motion": inputs.condition.motion, "silhouettes": kind, "elbows": {}}
    for k, (elbow, (shoulder, wrist)) in enumerate(ELBOWS.items()):
        true = [_point(inputs.truth, truth_names, n) for n in (shoulder, elbow, wrist)]
        rows = {}
        for name, run in (("pik", pik), ("ibik", ibik)):
            names = run.estimate.marker_names
            estimate = [_point(run.estimate.positions, names, n) for n in (shoulder, elbow, wrist)]
            rows[name] = decompose(*estimate, *true)
        # Without the swivel search (or the image) nothing was recorded: NaN before the image steps.
        before = (np.array([stage["before"][k] for stage in stages]) if len(stages) == frames
                  else np.full((frames, 3), np.nan))
        hinted = np.array([elbow in stage["hints"] for stage in stages]) if len(stages) == frames \
            else np.zeros(frames, dtype=bool)
        hint_error = np.array([np.linalg.norm(stage["hints"][elbow] - true[1][f]) if elbow in stage["hints"]
                               else np.nan for f, stage in enumerate(stages)]) if len(stages) == frames \
            else np.full(frames, np.nan)
        rows["ibik"]["before_image"] = np.linalg.norm(before - true[1], axis=1)
        rows["ibik"]["hinted"] = hinted
        rows["ibik"]["hint_error"] = hint_error
        if profiles and len(stages) == frames:
            names = ibik.estimate.marker_names
            rows["ibik"].update(profile_figures([stage["profile"] for stage in stages], k, true[1],
                                                _point(ibik.estimate.positions, names, elbow),
                                                [stage["hints"].get(elbow) for stage in stages]))
        out["elbows"][elbow] = {run: {key: value.tolist() for key, value in columns.items()}
                                for run, columns in rows.items()}
    return out


def summary_lines(result: dict) -> list[str]:
    lines = []
    for elbow, runs in result["elbows"].items():
        pik, ibik = runs["pik"], runs["ibik"]
        med = {key: float(np.median(value)) for key, value in ibik.items() if key in (
            "radius", "true_radius", "swivel_deg")}
        lines.append(
            f"{result['index']:3d} {result['motion']:15s} {result['silhouettes']:7s} {elbow}: "
            f"PIK {np.mean(pik['total'])*1e3:5.1f}"
            f" IBIK {np.mean(ibik['total'])*1e3:5.1f} mm (before image {np.mean(ibik['before_image'])*1e3:5.1f}); "
            f"IBIK radius {med['radius']*1e3:4.0f} (true {med['true_radius']*1e3:4.0f}) radius err "
            f"{np.mean(np.abs(ibik['radius_error']))*1e3:4.1f}, swivel {med['swivel_deg']:5.1f} deg "
            f"(PIK {np.median(pik['swivel_deg']):5.1f}), chord {np.mean(ibik['chord'])*1e3:5.1f}, along "
            f"{np.mean(np.abs(ibik['along_error']))*1e3:4.1f}; hinted {int(np.sum(ibik['hinted']))} frames")
        if "best_deg" in ibik:
            lines.append(profile_line(ibik))
    return lines


def profile_line(ibik: dict) -> str:
    """The tail frames (IBIK more than 25 mm off) by cause: lengths (the distance from the line off
    more than the swivel's chord), the criterion's peak elsewhere (> 20 deg from the truth; near-equal:
    the truth within 10 % of the range below it), the peak at the truth but the elbow elsewhere; and
    flips (the elbow's swivel turning > 30 deg between frames while the truth's turns < 10)."""
    total, chord = np.array(ibik["total"]), np.array(ibik["chord"])
    lengths_off = np.abs(np.array(ibik["radius_error"])) > chord
    best, final = np.abs(np.array(ibik["best_deg"])), np.abs(np.array(ibik["final_deg"]))
    deficit = np.array(ibik["truth_deficit"])
    tail = total > 0.025
    elsewhere = tail & ~lengths_off & (best > 20.0)
    followed = tail & ~lengths_off & (best <= 20.0) & (final > 20.0)
    true_turn = np.abs(_wrapped_deg(np.radians(np.diff(ibik["true_angle_deg"]))))
    turn = np.abs(_wrapped_deg(np.radians(np.diff(ibik["final_angle_deg"]))))
    flips = int(np.sum((turn > 30.0) & (true_turn < 10.0)))
    def median_of(key: str, chosen: np.ndarray) -> float:
        return float(np.median(np.abs(np.array(ibik[key])[chosen]))) if chosen.any() else float("nan")

    capped = ", ".join(f"{key[7:-4]} mm {np.median(np.abs(ibik[key])):.0f} / {np.percentile(np.abs(ibik[key]), 90):.0f}"
                       f" deg (tail {median_of(key, tail):.0f})" for key in ibik if key.startswith("capped_"))
    return (f"      tail {int(tail.sum())}/{tail.size} frames: lengths {int((tail & lengths_off).sum())}, "
            f"peak elsewhere {int(elsewhere.sum())} (near-equal {int((elsewhere & (deficit < 0.1)).sum())}), "
            f"peak at truth not followed {int(followed.sum())}; flips {flips}; all frames: best sample from truth "
            f"{np.median(best):.0f} / {np.percentile(best, 90):.0f} deg, final {np.median(final):.0f} / "
            f"{np.percentile(final, 90):.0f}, truth's deficit {np.median(deficit):.2f} / "
            f"{np.percentile(deficit, 90):.2f}, near-best width {np.median(ibik['flat_deg']):.0f} deg; where the "
            f"peak is elsewhere, each term's own best from the truth (median): overlap "
            f"{median_of('overlap_deg', elsewhere):.0f}, axis {median_of('axis_deg', elsewhere):.0f} deg; the peak "
            f"nearer the trunk's axis than the truth in {int((np.array(ibik['trunk_nearer'])[elsewhere] < 0).sum())}; "
            f"the arm's overlap capped, with the axis term, best from the truth (all frames median / p90): {capped}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, required=True, help="the folder sweep.py --keep wrote")
    parser.add_argument("--conditions", type=int, nargs="+", required=True)
    parser.add_argument("--silhouettes", default="clean")
    parser.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="a JSON of every frame's figures")
    parser.add_argument("--hint-unrefuted", action="store_true",
                        help="the swivel search hints limbs the silhouettes do not refute too (the earlier rule: "
                             "SwivelSearch.keep_unrefuted=False)")
    parser.add_argument("--target-filter", default="auto", help="ibik track --target-filter (default: the sweep's)")
    parser.add_argument("--profiles", action="store_true",
                        help="read the criterion around each elbow's circle per frame and sort the tail's "
                             "frames by cause")
    arguments = parser.parse_args(argv)
    if arguments.hint_unrefuted:  # the Tracker builds its SwivelSearch from its module's name
        tracker_module.SwivelSearch = functools.partial(SwivelSearch, keep_unrefuted=False)  # type: ignore[misc]
    overrides = parse_settings(arguments.settings)
    results = []
    for index in arguments.conditions:
        inputs = load_condition(draw_condition(index, arguments.seed), arguments.keep / f"condition_{index:03d}")
        if inputs is None:
            raise SystemExit(f"condition {index}: no kept files under {arguments.keep}; run sweep.py --keep first")
        for kind in arguments.silhouettes.split(","):
            result = diagnose(inputs, kind, overrides, arguments.profiles, arguments.target_filter)
            results.append(result)
            print("\n".join(summary_lines(result)), flush=True)
    if arguments.out is not None:
        arguments.out.write_text(json.dumps(results) + "\n")


if __name__ == "__main__":
    main()
