"""Simulated CAN servos: one firmware_protocol node per servo (SPEC.md §6) behind a simulated slcan adapter
(or, with ``transport="socketcand"``, a simulated socketcand daemon on loopback: `socketcand_server`).

Unmodified python-can opens :attr:`CanServoBus.path` with
``can.Bus(interface="slcan", channel=path, bitrate=1_000_000, sleep_after_open=0)``.
Node ``node_ids[i]`` owns plant joint ``i``, whose joint id is the node id and whose
name (in HELLO_ACK) is ``joint_names[i]``. Each node runs a `BoardEngine` over a
`PlantBackend` (see :mod:`sim_devices.firmware_board`; one `PlantJoints` for the whole
plant), so it answers HELLO, obeys SET_GOALS (its own or a broadcast's share), TORQUE,
WATCHDOG and STREAM_RATES, and streams JOINT_STATE / HEARTBEAT / STATUS. The optional
foot-sensor and IMU providers sit on node ``sensor_node`` (default the first), which then
also streams FOOT_SENSORS and IMU.

Faults (see `faults`), split by where they happen:

* ``drop``/``corrupt``/``delay`` act on each transfer a node sends (a whole message: lost,
  one data byte changed, or held back), so each is one lost or rejected message at the
  host. Only multi-frame transfers are corrupted: they carry the protocol's CRC-32, while
  a single frame with a bad bit never reaches a host on a real bus (CAN's own CRC drops
  it), so there the draw has no effect and is not counted;
* ``overload=ID@T`` latches OVERLOAD on node ``ID``'s joint and drops its torque;
* ``vanish`` and ``busoff`` are the adapter's (see `slcan_adapter`).

`CanServoBus.set_faults` swaps the node faults (drop, corrupt, delay, overload) at run time.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import replace

import can

import firmware_protocol as fp
from firmware_protocol.board import DEFAULT_RATES
from firmware_protocol.can_framing import BROADCAST
from sim_devices.can_node import CanFrame
from sim_devices.faults import FaultCounters, FaultInjector, FaultSpec, parse_faults
from sim_devices.firmware_board import FootProvider, ImuProvider, PlantBackend, PlantJoints, step_period
from sim_devices.pty_port import PtyPort
from sim_devices.servo_plant import JointPlant
from sim_devices.slcan_adapter import SlcanAdapter
from sim_devices.socketcand_server import SocketcandServer

NODE_FAULTS = frozenset({"drop", "corrupt", "delay", "overload"})
ADAPTER_FAULTS = frozenset({"vanish", "busoff"})
_NODE_SHIFT, _FROM_NODE_BIT, _LAST_BIT = 13, 1 << 20, 1 << 7


class _NodeBus:
    """The node's side of the bus, as the python-can bus `CanTransport` expects: frames in from the host,
    frames out collected for the adapter."""

    channel_info = "simulated CAN node"

    def __init__(self) -> None:
        self.inbox: deque[can.Message] = deque()
        self.outbox: list[tuple[int, bytes]] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.outbox.append((msg.arbitration_id, bytes(msg.data)))

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.inbox.popleft() if self.inbox else None


class CanServoNode:
    """One node on the simulated bus (a `CanNode`); its faults and lock are its `CanServoBus`'s."""

    def __init__(self, owner: CanServoBus, node: int, backend: PlantBackend, joint_names: Sequence[str],
                 rates: fp.StreamRates, status_period: float) -> None:
        self.node = node
        self.backend = backend
        self._owner = owner
        self._bus = _NodeBus()
        self.engine = fp.BoardEngine(fp.CanTransport(self._bus, node, role="board"), backend,
                                     joint_ids=backend.joint_ids, joint_names=list(joint_names), device_id=node,
                                     capabilities=backend.capabilities, rates=rates,
                                     status_period=status_period)
        self._next_step = 0.0
        self._held: list[tuple[float, list[CanFrame]]] = []  # delayed transfers: (due, frames)

    def on_frame(self, frame: CanFrame) -> list[CanFrame]:
        ident = frame.arbitration_id
        if not frame.is_extended or frame.is_remote or ident & _FROM_NODE_BIT \
                or (ident >> _NODE_SHIFT) & 0x7F not in (self.node, BROADCAST):
            return []  # not for us: cheap, since every node sees every frame
        with self._owner.lock:
            self._bus.inbox.append(can.Message(arbitration_id=ident, data=frame.data, is_extended_id=True))
            return self._step(time.monotonic())

    def tick(self, now: float) -> list[CanFrame]:
        with self._owner.lock:
            self._owner.fault_events(now)
            out = self._release(now) if self._held else []
            if now >= self._next_step:
                out += self._step(now)
            return out

    def _step(self, now: float) -> list[CanFrame]:
        self.engine.step(0.0)
        self._next_step = now + step_period(self.engine.rates)
        out: list[CanFrame] = []
        transfer: list[CanFrame] = []
        for ident, data in self._bus.outbox:
            transfer.append(CanFrame(ident, data, is_extended=True))
            if ident & _LAST_BIT:
                out += self._fate(transfer, now)
                transfer = []
        self._bus.outbox.clear()
        return out

    def _fate(self, transfer: list[CanFrame], now: float) -> list[CanFrame]:
        faults = self._owner.faults
        dropped, corrupt, delay = faults.reply_fate()
        if dropped:
            return []
        if corrupt and len(transfer) > 1:
            k = len(transfer) // 2
            hit = transfer[k]
            transfer[k] = CanFrame(hit.arbitration_id, faults.corrupt(hit.data, 0, len(hit.data)), is_extended=True)
        if delay:
            self._held.append((now + delay, transfer))
            return []
        return transfer

    def _release(self, now: float) -> list[CanFrame]:
        due = [frames for when, frames in self._held if when <= now]
        self._held = [(when, frames) for when, frames in self._held if when > now]
        return [frame for frames in due for frame in frames]


class CanServoBus:
    """Servo nodes ``node_ids`` (default 1..n) for ``plant``'s joints behind an slcan adapter at :attr:`path`.

    ``bitrate`` is the CAN bus bitrate (the host must open the adapter at it); ``rates`` the
    nodes' stream rates at power-up (SPEC.md default: JOINT_STATE 100 Hz, HEARTBEAT 10 Hz).
    Bad arguments raise ValueError naming them.
    """

    def __init__(self, plant: JointPlant, joint_names: Sequence[str], node_ids: Sequence[int] | None = None, *,
                 foot_sensors: FootProvider | None = None, imu: ImuProvider | None = None,
                 sensor_node: int | None = None, faults: str | FaultSpec = "", bitrate: int = 1_000_000,
                 rates: fp.StreamRates = DEFAULT_RATES,
                 status_period: float = 1.0, tick_period: float = 1e-3, name: str = "ttySLCAN",
                 transport: str = "slcan") -> None:
        nodes = list(range(1, len(joint_names) + 1)) if node_ids is None else list(node_ids)
        if len(nodes) != len(joint_names) or len(set(nodes)) != len(nodes) or not all(1 <= n <= 127 for n in nodes):
            raise ValueError(f"CanServoBus: need one distinct node id in 1..127 per joint name, got {nodes}")
        if len(plant.position) < len(nodes):
            raise ValueError(f"CanServoBus: plant has {len(plant.position)} joints for {len(nodes)} nodes")
        sensor_node = nodes[0] if sensor_node is None else sensor_node
        if sensor_node not in nodes:
            raise ValueError(f"CanServoBus: sensor_node {sensor_node} is not one of the nodes")
        spec = parse_faults(faults) if isinstance(faults, str) else faults
        unsupported = sorted(spec.fields - NODE_FAULTS - ADAPTER_FAULTS - {"seed"})
        if unsupported:
            raise ValueError(f"fault spec field '{unsupported[0]}' does not apply to CAN servos")
        self.lock = threading.Lock()
        self.faults = self._injector(spec, nodes)
        self.joints = PlantJoints(plant)
        self.nodes = [
            CanServoNode(self, node, PlantBackend(self.joints, [i], [node],
                                                  foot_sensors=foot_sensors if node == sensor_node else None,
                                                  imu=imu if node == sensor_node else None),
                         [joint_names[i]], rates, status_period)
            for i, node in enumerate(nodes)
        ]
        adapter_spec = replace(spec, drop=0.0, corrupt=0.0, delay_probability=0.0, delay=0.0, overloads=(),
                               fields=spec.fields & (ADAPTER_FAULTS | {"seed"}))
        self.transport = transport
        if transport == "socketcand":
            if adapter_spec.fields - {"seed"}:
                raise ValueError("fault spec: vanish and busoff are the slcan adapter's, not socketcand's")
            self.adapter = SocketcandServer(self.nodes, bitrate=bitrate, tick_period=tick_period)
            return
        if transport != "slcan":
            raise ValueError(f"CanServoBus: transport must be slcan or socketcand, got '{transport}'")
        self.adapter = SlcanAdapter(self.nodes, faults=adapter_spec, bus_bitrate=bitrate, tick_period=tick_period,
                                    name=name)

    # -- public API -------------------------------------------------------------------------------

    @property
    def path(self) -> str:
        """Device path to open with the client (stable across vanish/return)."""
        return self.adapter.path

    @property
    def port(self) -> PtyPort:
        """The adapter's pty port, e.g. to `PtyPort.vanish` / `PtyPort.restore` by hand."""
        return self.adapter.port

    @property
    def fault_counters(self) -> FaultCounters:
        """What was injected so far: the nodes' faults (current injector) and the adapter's vanishes/bus-offs."""
        node, adapter = self.faults.counters, self.adapter.fault_counters
        return replace(node, vanishes=adapter.vanishes, bus_offs=adapter.bus_offs)

    def set_faults(self, faults: str | FaultSpec) -> FaultCounters:
        """Inject node faults ``faults`` (drop, corrupt, delay, overload) from now on; returns the previous node
        injector's counters, final from here on."""
        spec = parse_faults(faults) if isinstance(faults, str) else faults
        injector = self._injector(spec, [n.node for n in self.nodes], adapter_faults=False)
        with self.lock:
            old, self.faults = self.faults, injector
        return old.counters

    def close(self) -> None:
        """Stop serving and remove the device path."""
        self.adapter.close()

    def __enter__(self) -> CanServoBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- used by the nodes, under the lock ------------------------------------------------------

    def fault_events(self, now: float) -> None:
        """Apply the node faults' timed events (overloads) that are due."""
        if now < self.faults.next_event_time():
            return
        for event in self.faults.due_events(now):
            for node in self.nodes:
                node.backend.overload(event.arg)

    @staticmethod
    def _injector(spec: FaultSpec, nodes: Sequence[int], adapter_faults: bool = True) -> FaultInjector:
        missing = sorted({servo for servo, _ in spec.overloads} - set(nodes))
        if missing:
            raise ValueError(f"fault spec field 'overload': no CAN node {missing[0]}")
        if not adapter_faults and spec.fields & ADAPTER_FAULTS:
            raise ValueError("set_faults: vanish and busoff are the adapter's, fixed when it starts")
        node_spec = replace(spec, vanishes=(), bus_offs=(), fields=spec.fields & (NODE_FAULTS | {"seed"}))
        injector = FaultInjector(node_spec, supported=NODE_FAULTS, device="CAN servo nodes")
        injector.start(time.monotonic())
        return injector
