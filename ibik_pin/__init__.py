"""ibik_pin: image-constrained inverse kinematics for human motion capture, on Pinocchio."""

__version__ = "0.1.0"
