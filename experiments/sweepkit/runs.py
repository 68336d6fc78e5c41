"""``ibik track`` on a condition's files, judged per joint group, and the summaries over conditions.

Groups: elbows (LElbow, RElbow) and knees (LKnee, RKnee), never targets, and the target keypoints
(their estimated position against the noise-free mocap joint, not against the noisy target). A
condition's figure for a group is the mean over its frames and the group's joints; summaries give
the median and the 90th percentile of those figures over conditions.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from realdata.runner import run_variant, variant

from ibik_pin.io.trc import TrcData, read_trc
from sweepkit.conditions import ConditionInputs

GROUPS = ("elbows", "knees", "targets")


@dataclass
class SweepRun:
    """One variant on one condition.

    Attributes:
        variant: "pik", "ibik1v", "ibik2v" or "ibik4v"; silhouettes: "clean" or "defects" (PIK:
            "none", the same run stands for both).
        errors: (F, 4) distance of LElbow, RElbow, LKnee, RKnee to the truth [m].
        target_errors: (F, T) distance of each target keypoint to its noise-free truth [m].
        estimate: the run's joints.trc (every keypoint of the model) [m].
    """

    index: int
    motion: str
    kind: str
    variant: str
    silhouettes: str
    errors: np.ndarray
    target_errors: np.ndarray
    wall_seconds: float
    estimate: TrcData | None = None

    def groups_mm(self) -> dict[str, float]:
        return {"elbows": float(np.mean(self.errors[:, :2]) * 1e3), "knees": float(np.mean(self.errors[:, 2:]) * 1e3),
                "targets": float(np.mean(self.target_errors) * 1e3)}

    def row(self) -> dict:
        return {"index": self.index, "motion": self.motion, "kind": self.kind, "variant": self.variant,
                "silhouettes": self.silhouettes, "groups_mm": self.groups_mm(),
                "joints_mm": dict(zip(("LElbow", "RElbow", "LKnee", "RKnee"),
                                      (float(v) for v in np.mean(self.errors, axis=0) * 1e3), strict=True)),
                "knee_p90_frames_mm": float(np.percentile(self.errors[:, 2:], 90) * 1e3),
                "elbow_p90_frames_mm": float(np.percentile(self.errors[:, :2], 90) * 1e3),
                "wall_seconds": self.wall_seconds}


def run_condition_variant(inputs: ConditionInputs, name: str, silhouettes: str, overrides: dict | None = None,
                          static: Path | None = None, target_filter: str | float = "off") -> SweepRun:
    """``ibik track`` on the condition's files with the variant (IBIK: the first N cameras;
    realdata.runner.run_variant); `static`: another static file than the condition's;
    `target_filter`: ``--target-filter``. The static already holds the lengths the sweep's
    ``--lengths`` chose (sweepkit/lengths.py), so ``ibik track`` runs with ``--trial-lengths off``:
    each variant's lengths are refined once, and the oracle's are the trial's own."""
    chosen = variant(name)
    scratch = Path(tempfile.mkdtemp(prefix="sweep_"))
    try:
        result = run_variant(dataclasses.replace(inputs, static_path=static), chosen, silhouettes, overrides,
                             scratch / "run", target_filter=target_filter, trial_lengths="off")
        estimate = read_trc(scratch / "run" / "joints.trc").in_metres()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    truth = inputs.truth[:, [inputs.truth_names.index(n) for n in inputs.target_names]]
    estimated = estimate.positions[:, [estimate.marker_names.index(n) for n in inputs.target_names]]
    condition = inputs.condition
    return SweepRun(condition.index, condition.motion, condition.kind, chosen.name,
                    "none" if not chosen.views else silhouettes, result.errors,
                    np.linalg.norm(estimated - truth, axis=2), result.wall_seconds, estimate)


def _stats(values: list[float]) -> dict:
    if not values:
        return {"median": None, "p90": None, "count": 0}
    return {"median": float(np.median(values)), "p90": float(np.percentile(values, 90)), "count": len(values)}


def summarize(runs: list[dict]) -> dict:
    """Median and 90th percentile over conditions per (variant, silhouettes) and group; the same
    per motion kind and per motion. PIK's runs count for both silhouette conditions."""
    summary: dict = {"all": {}, "by_kind": {}, "by_motion": {}}
    variants = list(dict.fromkeys(r["variant"] for r in runs))
    for silhouettes in ("clean", "defects"):
        if silhouettes != "clean" and not any(r["silhouettes"] == silhouettes for r in runs):
            continue  # no IBIK run with these silhouettes (PIK's stand under "clean")
        for name in variants:
            chosen = [r for r in runs if r["variant"] == name and r["silhouettes"] in (silhouettes, "none")]
            if not chosen:
                continue
            key = f"{name}/{silhouettes}"
            summary["all"][key] = {g: _stats([r["groups_mm"][g] for r in chosen]) for g in GROUPS}
            for field, bucket in (("kind", "by_kind"), ("motion", "by_motion")):
                for value in dict.fromkeys(r[field] for r in chosen):
                    subset = [r for r in chosen if r[field] == value]
                    summary[bucket].setdefault(value, {})[key] = {g: _stats([r["groups_mm"][g] for r in subset])
                                                                  for g in GROUPS}
    return summary


def _cell(stats: dict) -> str:
    if stats["median"] is None:
        return "-"
    return f"{stats['median']:.1f} / {stats['p90']:.1f}"


def markdown(summary: dict, header: str) -> str:
    """The tables: every condition, then per motion kind and per motion (2 views)."""
    lines = [header, "", "## All conditions: median / 90th percentile over conditions [mm]", "",
             "| variant | silhouettes | elbows | knees | targets |", "| --- | --- | ---: | ---: | ---: |"]
    for key, groups in summary["all"].items():
        name, silhouettes = key.split("/")
        lines.append(f"| {variant(name).label} | {silhouettes} | " + " | ".join(_cell(groups[g]) for g in GROUPS)
                     + " |")
    for bucket, title in (("by_kind", "motion kind"), ("by_motion", "motion")):
        lines += ["", f"## Per {title}, PIK vs IBIK 2 views: median / 90th percentile [mm]", "",
                  f"| {title} | conditions | PIK elbows | IBIK 2v elbows (clean) | IBIK 2v elbows (defects) | "
                  "PIK knees | IBIK 2v knees (clean) | IBIK 2v knees (defects) |",
                  "| --- | ---: |" + " ---: |" * 6]
        for value, table in summary[bucket].items():
            pik, clean, defects = (table.get(k) for k in ("pik/clean", "ibik2v/clean", "ibik2v/defects"))
            if pik is None or clean is None:
                continue
            defects = defects or {g: {"median": None} for g in GROUPS}
            lines.append(f"| {value} | {pik['knees']['count']} | {_cell(pik['elbows'])} | {_cell(clean['elbows'])} | "
                         f"{_cell(defects['elbows'])} | {_cell(pik['knees'])} | {_cell(clean['knees'])} | "
                         f"{_cell(defects['knees'])} |")
    return "\n".join(lines) + "\n"


def paired_markdown(runs: list[dict], filters: list[str]) -> str:
    """Each target filter against the first, paired by condition, per variant and group: the median
    and 90th percentile over conditions of each, the median change, and the conditions better or
    worse by more than 1 mm."""
    lines = ["## Target filters paired by condition: median / 90th percentile over conditions [mm]", "",
             "| variant | silhouettes | group | " + " | ".join(filters) +
             " | median change | better by > 1 mm | worse by > 1 mm (largest) |",
             "| --- | --- | --- |" + " ---: |" * (len(filters) + 3)]
    keys = list(dict.fromkeys((r["variant"], r["silhouettes"]) for r in runs))
    for name, silhouettes in keys:
        by_filter = {f: {r["index"]: r for r in runs if (r["variant"], r["silhouettes"]) == (name, silhouettes)
                         and r.get("target_filter", "off") == f} for f in filters}
        shared = sorted(set.intersection(*(set(rows) for rows in by_filter.values())))
        if not shared:
            continue
        for group in GROUPS:
            values = {f: [by_filter[f][i]["groups_mm"][group] for i in shared] for f in filters}
            change = np.subtract(values[filters[-1]], values[filters[0]])
            worse = change[change > 1.0]
            lines.append(f"| {variant(name).label} | {silhouettes} | {group} | "
                         + " | ".join(_cell(_stats(values[f])) for f in filters)
                         + f" | {np.median(change):+.1f} | {int(np.sum(change < -1.0))} of {len(shared)} | "
                         + f"{len(worse)} ({np.max(worse) if len(worse) else 0.0:.1f}) |")
    lines += ["", f"## Per motion, {filters[0]} -> {filters[-1]}: median over the motion's conditions [mm]", "",
              "| motion | variant | silhouettes | conditions | elbows | knees | targets |", "| --- | --- | --- |"
              + " ---: |" * 4]
    for motion in dict.fromkeys(r["motion"] for r in runs):
        for name, silhouettes in keys:
            chosen = [r for r in runs if (r["motion"], r["variant"], r["silhouettes"]) == (motion, name, silhouettes)]
            first = [r for r in chosen if r.get("target_filter", "off") == filters[0]]
            last = [r for r in chosen if r.get("target_filter", "off") == filters[-1]]
            if not first or not last:
                continue
            cells = [f"{np.median([r['groups_mm'][g] for r in first]):.1f} -> "
                     f"{np.median([r['groups_mm'][g] for r in last]):.1f}" for g in GROUPS]
            lines.append(f"| {motion} | {variant(name).label} | {silhouettes} | {len(first)} | " + " | ".join(cells)
                         + " |")
    return "\n".join(lines) + "\n"
