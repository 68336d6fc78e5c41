"""ibik_pin: image-constrained inverse kinematics for human motion capture, on Pinocchio."""

import os

# The solvers factor many tiny matrices (at most 42 x 42); OpenBLAS threads only add overhead to
# those, and on a loaded machine they make each factorisation 20-100 times slower. A user's own
# setting wins; it takes effect only if numpy has not been imported yet.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"
