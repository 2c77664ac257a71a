"""A servo robot as the live loop sees it: its body model and its config (feet, servos)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec, robot_body
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.robot_config import RobotConfig, find_robot_config, load_robot_config
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
    beside the URDF or built in."""
    path = Path(urdf) if urdf else demo_robot_path()
    body, spec = robot_body(path, UrdfBodyOptions(config=config))
    robot_config = load_robot_config(config) if config else find_robot_config(path, body.model.name)
    return Robot(path, body, robot_config, spec)
