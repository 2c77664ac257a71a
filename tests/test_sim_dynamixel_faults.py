"""Fault specs, and each injected fault as the unmodified dynamixel-sdk client sees it: the
client's error counts equal the injector's counters."""

from __future__ import annotations

import os
import re
import termios
import time

import pytest
import serial
from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
    PacketHandler,
    PortHandler,
)
from sim_support import sdk_latency_timer, short_gil_switch, wait_until  # noqa: F401 - fixtures

from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.faults import FaultInjector, FaultSpec, parse_faults

pytestmark = pytest.mark.usefixtures("short_gil_switch", "sdk_latency_timer")

IDS = list(range(1, 21))


def open_client(chain: DynamixelChain) -> tuple[PortHandler, PacketHandler]:
    port = PortHandler(chain.path)
    assert port.openPort()
    return port, PacketHandler(2.0)


# -- spec parsing ---------------------------------------------------------------------------------

def test_parse_full_spec():
    spec = parse_faults("drop=0.01, corrupt=0.02,delay=0.03:5ms,overload=7@2s,overload=9@1500ms,"
                        "vanish=3s+1s,busoff=0.5+250us,seed=11")
    assert spec == FaultSpec(drop=0.01, corrupt=0.02, delay_probability=0.03, delay=0.005,
                             overloads=((7, 2.0), (9, 1.5)), vanishes=((3.0, 1.0),),
                             bus_offs=((0.5, 250e-6),), seed=11, fields=spec.fields)
    assert spec.fields == {"drop", "corrupt", "delay", "overload", "vanish", "busoff", "seed"}
    assert parse_faults("") == FaultSpec()


@pytest.mark.parametrize(("spec", "message"), [
    ("drop=1.5", "field 'drop': expected a probability in [0, 1], got '1.5'"),
    ("corrupt=lots", "field 'corrupt': expected a probability"),
    ("delay=0.1", "field 'delay': expected PROBABILITY:TIME"),
    ("delay=0.1:5parsecs", "field 'delay': expected a time such as 2s, 5ms or 500us"),
    ("overload=300@1s", "field 'overload': expected ID@TIME with ID in 0..252"),
    ("vanish=3s", "field 'vanish': expected START+DURATION"),
    ("seed=-1", "field 'seed': expected a non-negative integer"),
    ("drop=0.1,drop=0.2", "field 'drop': given twice"),
    ("jitter=0.1", "fault spec item 'jitter=0.1': expected one of"),
])
def test_bad_spec_names_the_field(spec, message):
    with pytest.raises(ValueError, match=re.escape(message)) as info:
        parse_faults(spec)
    assert "\n" not in str(info.value)


def test_fields_a_device_does_not_support_are_refused():
    with pytest.raises(ValueError, match="field 'busoff' does not apply to the Dynamixel chain"):
        DynamixelChain([1], faults="busoff=1s+1s")
    with pytest.raises(ValueError, match="field 'overload': no servo with id 9 on this chain"):
        DynamixelChain([1], faults="overload=9@1s")


def test_injector_is_reproducible_and_counts_what_it_draws():
    draws = []
    for _ in range(2):
        injector = FaultInjector("drop=0.3,corrupt=0.3,delay=0.3:1ms,seed=5", supported=frozenset(
            {"drop", "corrupt", "delay"}), device="test")
        fates = [injector.reply_fate() for _ in range(1000)]
        draws.append(fates)
        assert injector.counters.dropped == sum(dropped for dropped, _, _ in fates)
        assert injector.counters.delayed == sum(delay > 0 for _, _, delay in fates)
    assert draws[0] == draws[1]
    assert 250 < draws[0].count((True, False, 0.0)) < 350


# -- faults through the client --------------------------------------------------------------------

def test_dropped_replies_are_client_timeouts():
    with DynamixelChain([1], faults="drop=0.25,seed=3", settings={"return_delay_time": 0}) as chain:
        port, ph = open_client(chain)
        results = [ph.ping(port, 1)[1] for _ in range(24)]
        port.closePort()
    assert set(results) == {COMM_SUCCESS, COMM_RX_TIMEOUT}
    assert results.count(COMM_RX_TIMEOUT) == chain.fault_counters.dropped


def test_corrupted_replies_are_client_crc_errors():
    with DynamixelChain([1], faults="corrupt=0.3,seed=4", settings={"return_delay_time": 0}) as chain:
        port, ph = open_client(chain)
        results = [ph.read4ByteTxRx(port, 1, 132)[1:] for _ in range(100)]
        port.closePort()
    assert set(results) == {(COMM_SUCCESS, 0), (COMM_RX_CORRUPT, 0)}
    assert results.count((COMM_RX_CORRUPT, 0)) == chain.fault_counters.corrupted


def test_delayed_replies_arrive_late_but_intact():
    with DynamixelChain([1], faults="delay=0.5:40ms,seed=2", settings={"return_delay_time": 0}) as chain:
        port, ph = open_client(chain)
        latencies = []
        for _ in range(30):
            start = time.perf_counter()
            assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)
            latencies.append(time.perf_counter() - start)
        port.closePort()
    late = sum(latency >= 0.040 for latency in latencies)
    assert 0 < late == chain.fault_counters.delayed


def test_a_dropped_reply_fails_that_sync_read_only():
    with DynamixelChain(IDS, faults="drop=0.02,seed=1", settings={"return_delay_time": 0}) as chain:
        port, ph = open_client(chain)
        reader = GroupSyncRead(port, ph, 132, 4)
        for dxl_id in IDS:
            reader.addParam(dxl_id)
        outcomes = []
        for _ in range(12):
            before = chain.fault_counters.dropped
            result = reader.txRxPacket()
            outcomes.append((result == COMM_SUCCESS, chain.fault_counters.dropped == before))
        port.closePort()
    assert all(ok == clean for ok, clean in outcomes)
    assert {ok for ok, _ in outcomes} == {True, False}


def test_injected_overload_shuts_down_until_reboot():
    with DynamixelChain([1, 2], faults="overload=2@0.1s", settings={"return_delay_time": 0}) as chain:
        port, ph = open_client(chain)
        assert ph.write1ByteTxRx(port, 2, 64, 1) == (COMM_SUCCESS, 0)
        assert wait_until(lambda: ph.read1ByteTxRx(port, 2, 70) == (0x20, COMM_SUCCESS, 0x80))
        assert chain.fault_counters.overloads == 1
        assert ph.read1ByteTxRx(port, 2, 64) == (0, COMM_SUCCESS, 0x80)  # torque went off
        assert ph.write1ByteTxRx(port, 2, 64, 1) == (COMM_SUCCESS, 0x81)  # result fail + alert
        assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)  # the other servo is fine
        assert ph.reboot(port, 2) == (COMM_SUCCESS, 0x80)  # acknowledged before rebooting
        assert ph.read1ByteTxRx(port, 2, 70) == (0, COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 2, 64, 1) == (COMM_SUCCESS, 0)
        port.closePort()


def test_port_vanishes_and_returns_at_the_same_path():
    with DynamixelChain([1], faults="vanish=0.2s+0.3s", settings={"return_delay_time": 0}) as chain:
        port, ph = open_client(chain)
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        assert wait_until(lambda: not os.path.exists(chain.path))
        with pytest.raises((serial.SerialException, termios.error, OSError)):
            ph.ping(port, 1)
        port.is_using = False  # the SDK leaves its busy flag set when the port raises
        assert wait_until(lambda: os.path.exists(chain.path))
        port.closePort()
        assert port.openPort()
        assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)
        assert chain.fault_counters.vanishes == 1
        port.closePort()
