#!/bin/bash
# `carlos` in the bridge image: ROS 2 jazzy's environment first (rclpy, its libraries, AMENT_PREFIX_PATH),
# then the carlos command of /opt/venv. Kubernetes may set `command: [carlos]` and so skip the image's
# ENTRYPOINT: this wrapper is what `carlos` resolves to on PATH, so either way ROS 2 is set up.
set -e
# shellcheck disable=SC1090,SC1091
source "/opt/ros/${ROS_DISTRO:-jazzy}/setup.bash" --
exec /opt/venv/bin/carlos "$@"
