#!/bin/bash
# `carlos` in the bridge image: ROS 2's environment first when the image has one (built with
# --build-arg ROS_IMAGE=ros:jazzy-…: rclpy, its libraries, AMENT_PREFIX_PATH for nodes run beside it), then
# the carlos command of /opt/venv. The default bridge image has no ROS 2 installation (the bridge speaks DDS
# through cyclonedds and knows the message types through rosbags), so there is nothing to source. Kubernetes
# may set `command: [carlos]` and so skip the image's ENTRYPOINT: this wrapper is what `carlos` resolves to
# on PATH, so either way the environment is set up.
set -e
setup="/opt/ros/${ROS_DISTRO:-jazzy}/setup.bash"
if [ -f "$setup" ]; then
  # shellcheck disable=SC1090
  source "$setup" --
fi
exec /opt/venv/bin/carlos "$@"
