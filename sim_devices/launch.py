"""Start a robot's simulated devices for one link kind: what ``livezmp sim --link KIND`` runs.

    devices = start_devices("dynamixel", plant, robot_config, joint_names=names, faults="drop=0.01")
    link = open_link(devices.url, names, robot_config)
    ...
    link.close()
    devices.close()

Plant joint ``i`` is ``joint_names[i]`` (default: the robot config's servo order); each
needs a ``[servos.NAME]`` entry in the robot config. Per kind:

* ``dynamixel``: one `DynamixelChain` of XM430s with the config's servo ids, bytes taking
  their wire time at ``baud`` behind a USB-serial ``adapter`` (:mod:`livezmp.links.bus_timing`);
  each servo's Homing Offset and Drive Mode are set so that its ticks follow the config's
  ``zero`` and ``direction`` (``ticks_per_rev`` must be 4096). Return Delay Time is left at
  the factory 250 (500 us) for the link to set at open. With ``buses`` > 1 the servos are
  split in config order over that many chains (ports), one URL ``dynamixel:PATH1+PATH2...``;
* ``can``: a `CanServoBus`, one node per servo (node id = servo id), behind an slcan adapter
  on a pty, or with ``can_transport="socketcand"`` a socketcand daemon on loopback TCP; with
  ``can_protocol="mit"`` MIT-mode motors instead (`mit_motor`: CAN id = servo id), split in
  order over ``buses`` CAN buses of one socketcand daemon (no foot sensors, IMU or faults);
* ``fw``: one `FirmwareBoard` with every joint (joint id = servo id).

``foot_sensors`` / ``imu`` providers (see `firmware_board`) reach the host on ``fw`` and
``can``; a Dynamixel chain has no such devices. ``faults`` is a fault spec (see `faults`).
`humanoid_sensors` makes them for a `SimHumanoid`:

    feet, imu = humanoid_sensors(humanoid)
    devices = start_devices("fw", humanoid, config, joint_names=body.joint_names, foot_sensors=feet, imu=imu)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from firmware_protocol import StreamRates
from livezmp.errors import InputError
from livezmp.links.base import FootSensors
from livezmp.links.bus_timing import DEFAULT_ADAPTER
from livezmp.model.robot_config import RobotConfig
from sim_devices.can_servo import CanServoBus
from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.dynamixel_imu_board import ImuBoard
from sim_devices.faults import FaultCounters, FaultSpec
from sim_devices.firmware_board import FirmwareBoard, FootProvider, ImuProvider
from sim_devices.humanoid import SimHumanoid
from sim_devices.mit_motor import MitMotorBuses
from sim_devices.plant_split import split_plant
from sim_devices.pty_port import PortServer, PtyPort
from sim_devices.servo_plant import JointPlant

KINDS = ("dynamixel", "can", "fw")
XM430_TICKS_PER_REV = 4096
XM430_ZERO = 2048  # the chain's tick at 0 rad before Homing Offset
# Twenty nodes at the SPEC's power-up rates (100 Hz JOINT_STATE, 3 frames each) send 6 000 frames/s, twice
# what python-can's slcan reader (one system call per byte) takes in on this kind of machine, so until the link
# sets its own rates the simulated nodes stream slowly.
CAN_POWER_UP_RATES = StreamRates(joint_state_hz=10, foot_sensors_hz=0, imu_hz=0, heartbeat_hz=2)


def humanoid_sensors(humanoid: SimHumanoid) -> tuple[FootProvider, ImuProvider]:
    """Foot-sensor and IMU providers reading ``humanoid`` in the devices' conventions.

    Feet: its force cells, one per sole corner, reordered front-left, front-right, rear-left,
    rear-right (x forward, y left in the foot link's frame; a quadrant without a corner, as
    under Romeo's triangular sole of three force sensors, is a cell that carries nothing), and
    their centre of pressure (m) from the sole's centre in that frame, None without load. IMU:
    orientation as (w, x, y, z), angular velocity (rad/s) and specific force (m/s^2) in the base
    link's axes. InputError if a foot has no sole of three or four corners, one per quadrant.
    """
    orders, offsets = {}, {}
    for side, foot in humanoid.body.feet.items():
        corners = None if foot.sole_local is None else np.asarray(foot.sole_local)[:, :2]
        if corners is None or not 3 <= len(corners) <= 4:
            raise InputError(f"foot '{side}': the simulated foot cells need a sole of three or four corners")
        rel = np.vstack([corners - corners.mean(axis=0), np.zeros(2)])  # the last row: a quadrant's empty cell
        order = []
        for front, left in ((True, True), (True, False), (False, True), (False, False)):
            hits = np.flatnonzero(((rel[:-1, 0] > 0) == front) & ((rel[:-1, 1] > 0) == left))
            if len(hits) > 1:
                raise InputError(f"foot '{side}': its sole corners are not at most one per quadrant around its "
                                 "centre")
            order.append(int(hits[0]) if len(hits) else len(corners))
        orders[side], offsets[side] = order, rel[order]

    def foot_sensors() -> FootSensors:
        cells = humanoid.foot_forces()
        forces = {side: np.append(getattr(cells, side), 0.0)[order] for side, order in orders.items()}
        cop = {side: (f @ offsets[side] / f.sum() if f.sum() > 0 else None) for side, f in forces.items()}
        return FootSensors(forces, cop)

    return foot_sensors, humanoid_imu(humanoid)


def humanoid_imu(humanoid: SimHumanoid) -> ImuProvider:
    """An IMU provider reading ``humanoid``: orientation as (w, x, y, z), angular velocity (rad/s)
    and specific force (m/s^2) in the base link's axes."""

    def imu() -> dict[str, np.ndarray]:
        reading = humanoid.imu()
        x, y, z, w = reading.quaternion
        return {"orientation": np.array([w, x, y, z]), "angular_velocity": np.asarray(reading.angular_velocity),
                "acceleration": np.asarray(reading.specific_force)}

    return imu


@dataclass
class SimDevices:
    """Running simulated devices: ``url`` is the link URL to open, ``ports`` their ptys (to vanish/restore),
    ``devices`` the device objects (a DynamixelChain, CanServoBus or FirmwareBoard)."""

    kind: str
    url: str
    ports: list[PtyPort]
    devices: list = field(default_factory=list)

    @property
    def fault_counters(self) -> FaultCounters:
        """What the devices injected so far, summed."""
        total = FaultCounters()
        for device in self.devices:
            for f in fields(FaultCounters):
                setattr(total, f.name, getattr(total, f.name) + getattr(device.fault_counters, f.name))
        return total

    def close(self) -> None:
        """Stop every device and remove its device path."""
        for device in self.devices:
            device.close()

    def __enter__(self) -> SimDevices:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def start_devices(kind: str, plant: JointPlant, robot_config: RobotConfig, *,
                  joint_names: Sequence[str] | None = None, faults: str | FaultSpec = "",
                  foot_sensors: FootProvider | None = None, imu: ImuProvider | None = None,
                  baud: int = 1_000_000, adapter: str | float = DEFAULT_ADAPTER, buses: int = 1,
                  can_transport: str = "slcan", can_protocol: str = "firmware") -> SimDevices:
    """Start the devices of ``kind`` ("dynamixel", "can" or "fw") driving ``plant`` (see module docstring).

    ``baud`` is the serial line rate (dynamixel, fw) or the CAN bitrate (can); ``adapter`` the
    Dynamixel bus's USB adapter (a name or ms). On a Dynamixel bus, ``imu`` is served by an IMU
    sub-controller (:class:`~sim_devices.dynamixel_imu_board.ImuBoard`) where the robot config
    has an ``[imu]`` (on the first bus). InputError on a bad kind, joint, servo entry,
    fault spec, baud or adapter.
    """
    if kind not in KINDS:
        raise InputError(f"simulated link kind '{kind}': expected one of {', '.join(KINDS)}")
    names = list(robot_config.servos) if joint_names is None else list(joint_names)
    if not names:
        raise InputError(f"{robot_config.source}: no [servos] entries: nothing to simulate")
    if len(plant.position) < len(names):
        raise InputError(f"the plant has {len(plant.position)} joints for {len(names)} joint names")
    servos = []
    for name in names:
        servo = robot_config.servos.get(name)
        if servo is None:
            raise InputError(f"{robot_config.source}: no [servos.{name}] entry for joint '{name}'")
        if kind != "dynamixel" and not (1 <= len(name) <= 16 and name.isascii() and name.isprintable()):
            raise InputError(f"joint '{name}': a firmware_protocol joint name is 1-16 printable ASCII characters")
        servos.append(servo)
    ids = [s.id for s in servos]
    try:
        if kind == "dynamixel":
            for s in servos:
                if s.ticks_per_rev != XM430_TICKS_PER_REV:
                    raise InputError(f"{robot_config.source}: [servos.{s.joint}] ticks_per_rev {s.ticks_per_rev}: "
                                     f"the simulated XM430 has {XM430_TICKS_PER_REV}")
            board = None if imu is None or robot_config.imu is None else \
                ImuBoard(robot_config.imu.id, imu, robot_config.imu.axes)
            return _dynamixel_buses(plant, servos, faults, baud, adapter, buses, board)
        if kind == "can" and can_protocol == "mit":
            if faults or foot_sensors is not None or imu is not None:
                raise InputError("simulated MIT-mode motors have no faults, foot sensors or IMU")
            motors = MitMotorBuses(plant, servos, buses=buses, bitrate=baud)
            return SimDevices(kind, motors.url, [], [motors])
        if kind == "can":
            if can_protocol != "firmware":
                raise InputError(f"CAN protocol '{can_protocol}': expected firmware or mit")
            bus = CanServoBus(plant, names, ids, foot_sensors=foot_sensors, imu=imu, faults=faults, bitrate=baud,
                              rates=CAN_POWER_UP_RATES, transport=can_transport)
            if can_transport == "socketcand":
                return SimDevices(kind, f"can:socketcand:{bus.adapter.channel}?{bus.adapter.url_options}", [], [bus])
            return SimDevices(kind, f"can:slcan:{bus.path}?bitrate={baud}&sleep_after_open=0", [bus.port], [bus])
        board = FirmwareBoard(plant, names, ids, foot_sensors=foot_sensors, imu=imu, faults=faults)
        return SimDevices(kind, f"fw:{board.path}?baud={baud}", [board.port], [board])
    except ValueError as err:
        if isinstance(err, InputError):
            raise
        raise InputError(str(err)) from None


def _dynamixel_buses(plant: JointPlant, servos: list, faults: str | FaultSpec, baud: int, adapter: str | float,
                     buses: int, board: ImuBoard | None = None) -> SimDevices:
    if not 1 <= buses <= len(servos):
        raise InputError(f"buses {buses}: must be 1..{len(servos)} (one servo at least on each)")
    sizes = [len(part) for part in np.array_split(np.arange(len(servos)), buses)]
    shares = [plant] if buses == 1 else split_plant(plant, sizes)
    chains = []
    server = PortServer(name="pty-dynamixel") if buses > 1 else None  # one thread serves every bus
    try:
        first = 0
        for share, size in zip(shares, sizes, strict=True):
            group = servos[first: first + size]
            first += size
            chain = DynamixelChain([s.id for s in group], share, faults=faults, baud_rate=baud, adapter=adapter,
                                   name=f"ttyDXL{len(chains)}", sub_controller=None if chains else board,
                                   port_server=server)
            chains.append(chain)
            for s in group:
                chain.set_register(s.id, "homing_offset", s.zero - XM430_ZERO)
                chain.set_register(s.id, "drive_mode", 1 if s.direction < 0 else 0)  # bit 0: reverse
    except BaseException:
        for chain in chains:
            chain.close()
        raise
    paths = "+".join(chain.path for chain in chains)
    return SimDevices("dynamixel", f"dynamixel:{paths}?baud={baud}", [c.port for c in chains], chains)
