"""The simulator's ``marsupial`` subcommands, registered in ``pyproject.toml`` under the entry-point
group ``marsupial.commands`` (see :mod:`mission.subcommands`). Importing this module imports none of them."""
from __future__ import annotations

from mission.subcommands import Subcommand

simulate = Subcommand("sim.simulate_cli:simulate",
                      "Integrate the paper's closed loop (one scenario, or a Monte-Carlo batch).")
mock_vehicle = Subcommand("sim.vehicle_cli:mock_vehicle", "Run the PX4-like kinematic MAVLink vehicle (SITL-free testing).")
ros2_robot = Subcommand("sim.ros2_robot:ros2_robot", "Run a ROS-2-shaped robot over Zenoh (Twist cmd_vel in, Odometry out).")
demo = Subcommand("sim.demo:demo", "Mock vehicle + carrier simulator + mission, on embedded defaults.")
