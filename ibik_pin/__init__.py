"""ibik_pin: image-constrained inverse kinematics for human motion capture, on Pinocchio.

Importing the package imports nothing heavy and changes nothing in the environment: the `ibik`
command sets its own OpenBLAS thread count (see :mod:`ibik_pin.cli`).
"""

__version__ = "0.1.0"
