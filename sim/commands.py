"""The simulator's ``marsupial`` subcommands, registered in ``pyproject.toml`` under the entry-point
group ``marsupial.commands`` (see :mod:`mission.cli.subcommands`). Importing this module imports none of them."""
from __future__ import annotations

from mission.cli.subcommands import Subcommand

simulate = Subcommand("sim.batch.simulate:simulate",
                      "Integrate the paper's closed loop (one scenario, or a Monte-Carlo batch).")
mock_vehicle = Subcommand("sim.vehicle.cli:mock_vehicle", "Run the PX4-like kinematic MAVLink vehicle (SITL-free testing).")
ros2_robot = Subcommand("sim.robots.ros2:ros2_robot", "Run a ROS-2-shaped robot over Zenoh (Twist cmd_vel in, Odometry out).")
demo = Subcommand("sim.demo:demo", "Mock vehicle + carrier simulator + mission, on embedded defaults.")
sitl_camera = Subcommand("sim.sitl.camera:sitl_camera",
                         "Render the passenger's downward camera from PX4 SITL's SIH truth and publish its frames.")
