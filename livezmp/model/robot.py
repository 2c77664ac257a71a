"""A servo robot as the live loop sees it: its body model and its config (feet, servos)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec, robot_body
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.robot_config import RobotConfig, ServoConfig, find_robot_config, load_robot_config
from livezmp.model.urdf_body import UrdfBodyOptions


@dataclass
class Robot:
    """A robot's body model and its config (feet, servos), from ``--robot`` / ``--robot-config``;
    ``spec`` what the body was built from (for a recording)."""

    urdf: Path
    body: BodyModel
    config: RobotConfig
    spec: BodySpec


def load_robot(urdf: str | None, config: str | None) -> Robot:
    """The robot of ``urdf`` (default: the built-in livezmp_mini) with its config: ``config``, else
    beside the URDF or built in; a config without servos gets ids 1, 2, ... in joint order (zero tick
    2048, direction +1), as a servo link needs one for every joint."""
    path = Path(urdf) if urdf else demo_robot_path()
    body, spec = robot_body(path, UrdfBodyOptions(config=config))
    robot_config = load_robot_config(config) if config else find_robot_config(path, body.model.name)
    if not robot_config.servos:  # a humanoid without a config: servo ids 1, 2, ... in joint order
        robot_config = replace(robot_config, servos={name: ServoConfig(name, i + 1)
                                                     for i, name in enumerate(body.joint_names)})
    return Robot(path, body, robot_config, spec)
