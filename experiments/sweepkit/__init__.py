"""Support code of experiments/sweep.py: many seeded conditions on real motion capture.

Each condition draws a motion window, a camera rig, a silhouette body, a static take whose segment
lengths are off the trial's, a target noise and a keypoint set; the files a user would bring to
``ibik track`` are written, then PIK and IBIK (1, 2, 4 views; clean and defective silhouettes) run
on them. Nothing is rendered from the tracking model: the silhouettes are those of capsules and
ellipsoids around the raw mocap skeleton (realdata.body), widened, flattened or loosened here.

- motions.py: the motion windows (every recording in the shared data folder) and their statics.
- body.py: the silhouette body with drawn limb radii, elliptical sections and loose clothing.
- conditions.py: the seeded draw of a condition and the files written for it.
- stats.py: errors per joint group, medians and 90th percentiles over conditions, the tables.
"""
