"""`livezmp demo`: the live loop on a simulated humanoid.

``livezmp_mini`` (or any humanoid's URDF: ``--robot``) on a simulated Dynamixel bus (or
``--link can|fw``) served by a child process (:class:`sim_devices.process.SimProcess`: its
own core and interpreter, as a robot is another machine; ``--link mock`` steps the
humanoid in this process instead), a
scenario (by default: lean past the toes and back, then swing the arms), a live status
line and the summary, with the simulator's own verdict (``fell``,
``true_inside_fraction``: the share of its 1 ms steps whose true ZMP was inside the
support polygon). The simulator runs on the last CPU the loop is not pinned to (``--sim-cpu``).
"""

from __future__ import annotations

import argparse
import sys

from livezmp.commands.run import (
    check_outputs,
    check_realtime,
    duration_of,
    finish,
    loop_cpus,
    loop_priority,
    run_loop,
)
from livezmp.commands.startup import Startup, closing_link
from livezmp.errors import InputError
from livezmp.links import LinkError, make_link
from livezmp.live import scenarios as sc
from livezmp.live.realtime import parse_cpus
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import Robot, load_robot
from sim_devices.launch import humanoid_sensors
from sim_devices.mock_link import MockLink
from sim_devices.process import SimProcess, beside_loop, check_faults, device_options, start_sim


def demo_in_process(robot: Robot, args: argparse.Namespace, scenario: sc.Scenario, startup: Startup) -> dict:
    """The mock link: the humanoid stepped by the loop's own reads, in this process."""
    startup.enter("starting the simulator")
    sim = start_sim(robot, "mock", scenario, args.fault)
    feet, imu = humanoid_sensors(sim.humanoid)
    with closing_link(MockLink(sim.humanoid, robot.body.joint_names, foot_sensors=feet, imu=imu), startup) as link:
        sim.start_scenario()
        summary = run_loop(link, robot, args, scenario.goals, duration_of(args, scenario.duration), fell=sim.fell,
                           source="mock:", startup=startup)
    return {**summary, **sim.verdict(), "link_url": "mock:"}


def demo_with_devices(robot: Robot, args: argparse.Namespace, scenario: sc.Scenario, startup: Startup) -> dict:
    """A real link (dynamixel-sdk, python-can, pyserial) to the simulator in a child process."""
    startup.enter("starting the simulator")
    with SimProcess(args.link, (args.scenario, {}), args.fault, urdf=args.robot, config=args.robot_config,
                    realtime_priority=max(loop_priority(args)[0] - 1, 0), devices=device_options(args),
                    cpus=simulator_cpus(args)) as sim:
        placed = sorted(sim.cpus())
        url = sim.url + (f"&{args.link_options}" if args.link_options else "")
        with closing_link(make_link(url, robot.body.joint_names, robot.config), startup) as link:
            sim.start_scenario()
            summary = run_loop(link, robot, args, scenario.goals, duration_of(args, scenario.duration),
                               fell=sim.fell, source=url, startup=startup)
        return {**summary, **sim.verdict(), "link_url": url, "simulator_cpus": placed}


def simulator_cpus(args: argparse.Namespace) -> frozenset[int] | None:
    """--sim-cpu: the CPUs for the simulator's devices and physics (None: anywhere); by default the last CPU
    outside --cpu (`beside_loop`). InputError on a bad one."""
    if args.sim_cpu is not None and args.link == "mock":
        raise InputError("--sim-cpu: the mock link's humanoid steps in the loop's own process")
    if args.sim_cpu == "any":
        return None
    return beside_loop(loop_cpus(args)) if args.sim_cpu is None else parse_cpus(args.sim_cpu, "--sim-cpu")


def cmd_demo(args: argparse.Namespace) -> int:
    startup = args.startup  # livezmp.cli.main's: a signal during the start-up is told (commands.startup)
    startup.enter("checking the options")
    check_realtime(args)
    check_outputs(args)
    device_options(args)  # bad --baud, --adapter or --buses are told before anything starts
    simulator_cpus(args)
    check_faults(args.fault)
    startup.enter("loading the robot")
    robot = load_robot(args.robot, args.robot_config)
    scenario = make_scenario(args.scenario, robot.body)
    try:
        summary = (demo_in_process if args.link == "mock" else demo_with_devices)(robot, args, scenario, startup)
    except LinkError as e:
        print(f"livezmp: error: {e}", file=sys.stderr)
        return 1
    summary["scenario"] = scenario.name
    return finish(summary, args)
