"""Sensors: lidar and depth/semantic camera by raycasting (open3d), ground truth, ROS 2 messages.

open3d is imported only when a scene is built (`simcore.sensors.scene.RoadScene`)."""
