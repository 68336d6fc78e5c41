"""Tasks: least-squares tasks (position, posture) and gradient tasks (the image criterion)."""

from ibik_pin.tasks.base import GradientTask, Task
from ibik_pin.tasks.image import ImageTask, View
from ibik_pin.tasks.position import FramePositionTask
from ibik_pin.tasks.posture import PostureTask

__all__ = ["Task", "GradientTask", "FramePositionTask", "PostureTask", "ImageTask", "View"]
