"""The model fitted to one subject: segment lengths from keypoints (scaling) and, as OpenSim's Scale
tool does, the placement of every keypoint on its segment from a static trial (calibration); the
calibrated subject written as a URDF whose keypoints are fixed links (urdf)."""
