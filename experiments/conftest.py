"""Lets the experiments' tests import the experiments' own support package (experiments/paper)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
