"""File formats: motion capture (TRC, MOT, BVH, ASF/AMC), calibration (Pose2Sim TOML), silhouette
masks and videos, and a tracked motion written for other programs (export).

Every reader raises :class:`~ibik_pin.exceptions.FileFormatError` naming the file and line, and
every writer writes atomically (:mod:`ibik_pin.io.files`).
"""
