"""Tasks: least-squares tasks (position, posture) and gradient tasks (the image criterion)."""

from .base import GradientTask, Task
from .image import ImageTask, View
from .position import FramePositionTask
from .posture import PostureTask

__all__ = ["Task", "GradientTask", "FramePositionTask", "PostureTask", "ImageTask", "View"]
