"""The Dynamixel XM430-W350 control table (Protocol 2.0), as data.

Addresses, sizes, access, initial values and value ranges follow the ROBOTIS
e-manual page for the XM430-W350 (firmware 45+). Indirect addresses are not
modelled. Each servo keeps its table as one preallocated ``bytearray`` of
`TABLE_SIZE` bytes, little-endian like the wire; `Field.fmt` is its struct code.

Goal PWM/Current/Velocity/Position have ranges that depend on limit registers;
those are checked by the servo, not here (``lo``/``hi`` are the widest range).
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass

TABLE_SIZE = 148
EEPROM_END = 64  # addresses below are EEPROM: writable only with torque off

MODEL_NUMBER = 1020  # XM430-W350
FIRMWARE_VERSION = 46  # Fast Sync/Bulk Read need 45 or later
BAUD_RATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000,
              7: 4_500_000}

# Hardware Error Status bits
INPUT_VOLTAGE_ERROR = 0x01
OVERHEATING_ERROR = 0x04
MOTOR_ENCODER_ERROR = 0x08
ELECTRICAL_SHOCK_ERROR = 0x10
OVERLOAD_ERROR = 0x20

# Units
POSITION_TICKS_PER_REV = 4096
VELOCITY_UNIT = 0.229 * 2 * 3.141592653589793 / 60.0  # rad/s per unit (0.229 rpm)
CURRENT_UNIT = 2.69e-3  # A per unit
PWM_FULL_SCALE = 885  # units for 100 % duty
VOLTAGE_UNIT = 0.1  # V per unit
WATCHDOG_UNIT = 0.020  # s per unit
RETURN_DELAY_UNIT = 2e-6  # s per unit


@dataclass(frozen=True)
class Field:
    """One control-table item: ``size`` bytes at ``address``; values in the table's units."""

    name: str
    address: int
    size: int
    writable: bool
    initial: int
    lo: int
    hi: int
    signed: bool = False

    @property
    def end(self) -> int:
        return self.address + self.size

    @property
    def eeprom(self) -> bool:
        return self.address < EEPROM_END

    @functools.cached_property  # read for every servo of every sync write: made once
    def fmt(self) -> str:
        code = {1: "b", 2: "h", 4: "i"}[self.size]
        return "<" + (code if self.signed else code.upper())


def _f(name: str, address: int, size: int, access: str, initial: int, lo: int = 0, hi: int | None = None,
       signed: bool = False) -> Field:
    if hi is None:
        hi = (1 << (8 * size - 1)) - 1 if signed else (1 << (8 * size)) - 1
    return Field(name, address, size, access == "RW", initial, lo, hi, signed)


FIELDS: tuple[Field, ...] = (
    # EEPROM area
    _f("model_number", 0, 2, "R", MODEL_NUMBER),
    _f("model_information", 2, 4, "R", 0),
    _f("firmware_version", 6, 1, "R", FIRMWARE_VERSION),
    _f("id", 7, 1, "RW", 1, 0, 252),
    _f("baud_rate", 8, 1, "RW", 1, 0, 7),
    _f("return_delay_time", 9, 1, "RW", 250, 0, 254),
    _f("drive_mode", 10, 1, "RW", 0, 0, 13),
    _f("operating_mode", 11, 1, "RW", 3, 0, 16),
    _f("secondary_id", 12, 1, "RW", 255, 0, 255),
    _f("protocol_type", 13, 1, "RW", 2, 1, 2),
    _f("homing_offset", 20, 4, "RW", 0, -1_044_479, 1_044_479, signed=True),
    _f("moving_threshold", 24, 4, "RW", 10, 0, 1023),
    _f("temperature_limit", 31, 1, "RW", 80, 0, 100),
    _f("max_voltage_limit", 32, 2, "RW", 160, 95, 160),
    _f("min_voltage_limit", 34, 2, "RW", 95, 95, 160),
    _f("pwm_limit", 36, 2, "RW", 885, 0, 885),
    _f("current_limit", 38, 2, "RW", 1193, 0, 1193),
    _f("acceleration_limit", 40, 4, "RW", 32767, 0, 32767),
    _f("velocity_limit", 44, 4, "RW", 350, 0, 1023),
    _f("max_position_limit", 48, 4, "RW", 4095, 0, 4095),
    _f("min_position_limit", 52, 4, "RW", 0, 0, 4095),
    _f("startup_configuration", 60, 1, "RW", 0, 0, 3),
    _f("shutdown", 63, 1, "RW", 52, 0, 255),
    # RAM area
    _f("torque_enable", 64, 1, "RW", 0, 0, 1),
    _f("led", 65, 1, "RW", 0, 0, 1),
    _f("status_return_level", 68, 1, "RW", 2, 0, 2),
    _f("registered_instruction", 69, 1, "R", 0),
    _f("hardware_error_status", 70, 1, "R", 0),
    _f("velocity_i_gain", 76, 2, "RW", 1920, 0, 16383),
    _f("velocity_p_gain", 78, 2, "RW", 100, 0, 16383),
    _f("position_d_gain", 80, 2, "RW", 0, 0, 16383),
    _f("position_i_gain", 82, 2, "RW", 0, 0, 16383),
    _f("position_p_gain", 84, 2, "RW", 800, 0, 16383),
    _f("feedforward_2nd_gain", 88, 2, "RW", 0, 0, 16383),
    _f("feedforward_1st_gain", 90, 2, "RW", 0, 0, 16383),
    _f("bus_watchdog", 98, 1, "RW", 0, -1, 127, signed=True),
    _f("goal_pwm", 100, 2, "RW", 0, -885, 885, signed=True),
    _f("goal_current", 102, 2, "RW", 0, -1193, 1193, signed=True),
    _f("goal_velocity", 104, 4, "RW", 0, -1023, 1023, signed=True),
    _f("profile_acceleration", 108, 4, "RW", 0, 0, 32767),
    _f("profile_velocity", 112, 4, "RW", 0, 0, 32767),
    _f("goal_position", 116, 4, "RW", 0, -1_048_575, 1_048_575, signed=True),
    _f("realtime_tick", 120, 2, "R", 0, 0, 32767),
    _f("moving", 122, 1, "R", 0),
    _f("moving_status", 123, 1, "R", 0),
    _f("present_pwm", 124, 2, "R", 0, signed=True),
    _f("present_current", 126, 2, "R", 0, signed=True),
    _f("present_velocity", 128, 4, "R", 0, signed=True),
    _f("present_position", 132, 4, "R", 0, signed=True),
    _f("velocity_trajectory", 136, 4, "R", 0, signed=True),
    _f("position_trajectory", 140, 4, "R", 0, signed=True),
    _f("present_input_voltage", 144, 2, "R", 120),
    _f("present_temperature", 146, 1, "R", 36),
    _f("backup_ready", 147, 1, "R", 0),
)

BY_NAME: dict[str, Field] = {field.name: field for field in FIELDS}
OPERATING_MODES = frozenset({0, 1, 3, 4, 5, 16})
POSITION_MODES = frozenset({3, 4, 5})  # position, extended position, current-based position
GOAL_FIELDS = frozenset({"goal_pwm", "goal_current", "goal_velocity", "goal_position"})


def field(name: str) -> Field:
    """The field called ``name``; a clear KeyError naming it otherwise."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise KeyError(f"no control-table field '{name}' on the XM430-W350") from None


def initial_table() -> bytearray:
    """A fresh control table holding the factory initial values."""
    table = bytearray(TABLE_SIZE)
    for item in FIELDS:
        struct.pack_into(item.fmt, table, item.address, item.initial)
    return table


@functools.cache
def fields_in(start: int, end: int) -> tuple[tuple[Field, ...], bool]:
    """Fields overlapping bytes [start, end) and whether every byte there belongs to one."""
    covered = [item for item in FIELDS if item.address < end and item.end > start]
    owned = sum(min(item.end, end) - max(item.address, start) for item in covered)
    return tuple(covered), owned == end - start
