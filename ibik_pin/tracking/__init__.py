"""The per-frame algorithm: a recorded sequence solved frame after frame, warm-started.

The tracker (tracker) and its settings (settings), the priority levels and stacks (levels, stack),
the first frame's pose search (first_frame), the swivel search of free elbows and knees (swivel),
the image views (views), the levels' outcomes (outcomes) and what a run gives (result). It may
import the model, tasks, solvers, vision and the read-ahead plumbing (ibik_pin.readahead), never
the application (ibik_pin.app).
"""

from ibik_pin.tracking.result import TrackingResult
from ibik_pin.tracking.settings import TrackingSettings
from ibik_pin.tracking.tracker import Tracker

__all__ = ["Tracker", "TrackingSettings", "TrackingResult"]
