"""An example closed-loop controller: a lane-holding cruise controller as a ROS 2-style node."""

from examples.controller.node import CruiseController

__all__ = ["CruiseController"]
