#!/usr/bin/env bash
# rospy vs SGM's bridge: decoding and reading a 20k-point Velodyne cloud, same run. Needs
# Debian's ROS 1 Python packages (python3-sensor-msgs), as .ci/run installs them.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo bench -p sgm-bridge --bench bridge -- --noplot >/dev/null 2>target/compare_rospy.log || { cat target/compare_rospy.log; exit 1; }
exec /usr/bin/python3 benches/compare_rospy.py target/criterion
