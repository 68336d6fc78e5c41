"""OpenSim's inverse kinematics run on an `ibik track` output, for the tests that check it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

# Every coordinate of OpenSim's fit within this of motion.mot, RMS over the frames: rotations [deg],
# the pelvis' translations [m].
RMS_TOLERANCE_DEG = 1.0
RMS_TOLERANCE_M = 1e-3
TRANSLATIONS = ("pelvis_tx", "pelvis_ty", "pelvis_tz")


def worst_beyond_tolerance(rms: dict[str, float]) -> list[str]:
    """The coordinates whose RMS exceeds their tolerance, with their figure."""
    return [f"{label}: {value:.3g}" for label, value in sorted(rms.items(), key=lambda item: -item[1])
            if value >= (RMS_TOLERANCE_M if label in TRANSLATIONS else RMS_TOLERANCE_DEG)]


def opensim_ik_rms_deg(out: Path, work: Path) -> dict[str, float]:
    """OpenSim's InverseKinematicsTool on out/joints.trc with out/model.osim, every marker weighted
    1: per coordinate, the RMS over the frames of its difference to out/motion.mot [deg or m]."""
    opensim = pytest.importorskip("opensim", reason="OpenSim's Python package (pip install 'ibik_pin[opensim]')")
    model = opensim.Model(str(out / "model.osim"))
    markers = opensim.TimeSeriesTableVec3(str(out / "joints.trc"))
    tool = opensim.InverseKinematicsTool()
    tool.setModel(model)
    tool.setMarkerDataFileName(str(out / "joints.trc"))
    times = markers.getIndependentColumn()
    tool.setStartTime(times[0])
    tool.setEndTime(times[-1])
    tool.setResultsDir(str(work))
    tool.setOutputMotionFileName(str(work / "ik.mot"))
    tool.set_report_errors(False)
    for name in markers.getColumnLabels():
        task = opensim.IKMarkerTask()
        task.setName(name)
        task.setWeight(1.0)
        task.setApply(True)
        tool.getIKTaskSet().cloneAndAppend(task)
    assert tool.run()
    fitted = opensim.TimeSeriesTable(str(work / "ik.mot"))
    played = opensim.TimeSeriesTable(str(out / "motion.mot"))
    return {label: float(np.sqrt(np.mean((fitted.getDependentColumn(label).to_numpy()
                                          - played.getDependentColumn(label).to_numpy()) ** 2)))
            for label in played.getColumnLabels()}
