"""`livezmp sim`: a simulated humanoid (:class:`sim_devices.humanoid.SimHumanoid`) behind
simulated devices of one link kind on ptys; prints one JSON line (the link URL and port
paths) and runs until stopped."""

from __future__ import annotations

import argparse
import json
import sys
import threading

from livezmp.commands.common import stop_on_signals
from livezmp.live.realtime import check_priority, realtime_priority
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import load_robot
from sim_devices.process import check_faults, device_options, sim_process_setup, start_sim


def cmd_sim(args: argparse.Namespace) -> int:
    check_priority(args.realtime_priority)
    robot = load_robot(args.robot, args.robot_config)
    scenario = make_scenario(args.scenario, robot.body)
    check_faults(args.fault)
    devices = device_options(args)
    sim_process_setup()
    stop = threading.Event()
    # the devices' threads inherit the priority: they stand in for hardware, which no other
    # program on the computer delays
    with realtime_priority(args.realtime_priority) as refused:
        sim = start_sim(robot, args.link, scenario, args.fault, **devices)
        try:
            sim.start_scenario()
            print(json.dumps({"link": args.link, "url": sim.devices.url, "ports": [p.path for p in sim.devices.ports],
                              "robot": str(robot.urdf), "placeholder_inertias": list(robot.body.placeholder_inertias),
                              "scenario": scenario.name, "faults": args.fault,
                              "realtime_priority": args.realtime_priority if refused is None else 0}), flush=True)
            with stop_on_signals(lambda _name: stop.set()):
                while not stop.wait(0.2):
                    pass
        finally:
            sim.close()
    v = sim.verdict()
    print(f"livezmp sim: stopped; the robot {'fell: ' + v['fall'] if v['fell'] else 'did not fall'}",
          file=sys.stderr, flush=True)
    return 0
