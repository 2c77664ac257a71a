"""A simulated IMU sub-controller on a Dynamixel bus: the OP3's OpenCR board as the bus sees it.

Its control table follows the vendor's device file (ROBOTIS-Framework
``robotis_device/devices/sensor/OPEN-CR.device``; the layout and units are in
:mod:`livezmp.links.dynamixel_imu`): ID at 3, Return Delay Time at 5 (2 us units),
Status Return Level at 16, button at 30, present voltage at 31 (0.1 V), gyro at 32-37 and
accelerometer at 38-43, refreshed from the IMU provider whenever they are read. It answers
Ping, Read and its part of Sync/Bulk (and Fast) Reads; writes are not modelled (the loop
never writes it). Its Model Number reads 0: the device file does not give the board's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from livezmp.links.dynamixel_imu import IMU_ADDRESS, IMU_LENGTH, encode_imu

TABLE_SIZE = 51  # up to imu_control (address 50)
ID, RETURN_DELAY, STATUS_RETURN_LEVEL, VOLTAGE = 3, 5, 16, 31
RETURN_DELAY_UNIT = 2e-6  # s
ImuProvider = Callable[[], dict[str, np.ndarray]]


class ImuBoard:
    """Sub-controller ``dxl_id`` whose IMU reads ``imu()`` (the links' IMU dict: base-link
    ``angular_velocity`` rad/s and ``acceleration`` m/s²), its axes turned by ``axes`` (the
    sign of each board axis in the base link's, as the board is mounted)."""

    def __init__(self, dxl_id: int, imu: ImuProvider, axes: Sequence[int] = (1, 1, 1)) -> None:
        if not 0 <= dxl_id <= 252:
            raise ValueError(f"ImuBoard: id must be in 0..252, got {dxl_id}")
        self.imu = imu
        self.axes = tuple(axes)
        self.table = bytearray(TABLE_SIZE)
        self.table[ID] = dxl_id
        self.table[STATUS_RETURN_LEVEL] = 2
        self.table[VOLTAGE] = 120  # 12.0 V
        self.reads = 0  #: reads that included the IMU registers

    @property
    def id(self) -> int:
        return self.table[ID]

    @property
    def return_delay(self) -> float:
        return self.table[RETURN_DELAY] * RETURN_DELAY_UNIT

    @property
    def status_level(self) -> int:
        return self.table[STATUS_RETURN_LEVEL]

    def read(self, address: int, length: int) -> bytes | None:
        """``length`` bytes from ``address``, the IMU registers fresh; None beyond the table."""
        if length == 0 or address + length > TABLE_SIZE:
            return None
        if address < IMU_ADDRESS + IMU_LENGTH and address + length > IMU_ADDRESS:
            reading = self.imu()
            self.table[IMU_ADDRESS: IMU_ADDRESS + IMU_LENGTH] = encode_imu(
                reading["angular_velocity"], reading["acceleration"], self.axes)
            self.reads += 1
        return bytes(self.table[address: address + length])
