"""Support code of experiments/real_mocap.py: a benchmark on raw motion capture, without the inverse crime.

Targets, truth and silhouettes all come from the raw mocap skeleton (never from the tracking model):
the targets and the truth are its joints mapped to Pose2Sim keypoints, the silhouettes those of
another body (tapered capsules and ellipsoids of adult proportions around every joint of the mocap
skeleton). ``ibik track`` (run_track) then solves the files a user would bring.

- clips.py: the clips (files, windows, static trials), resampling to 60 Hz, the mocap joints in the
  keypoints' frame.
- body.py: the mocap body and its rendering (silhouettes, per-limb masks, a preview).
- inputs.py: the files written for ``ibik track`` (targets, static, calibration, masks), cached.
- runner.py: one variant on one clip, the full grid, the tables.
"""
