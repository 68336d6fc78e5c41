"""The project's URDF models (the paper's planar chain, arm and leg), installed as ``ibik_pin.models``."""
