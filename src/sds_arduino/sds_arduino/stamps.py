"""The Arduino's records stamped on one clock, in order, from the first record on.

A record's stamp is its device time mapped onto the host's clock (`DeviceClock`) and, once the
sync LED has been seen both commanded by the device and in the video, shifted onto the camera's
clock. Neither is known at the first record: the mapping needs a few seconds of records, the
LED comes at the start of a drop. Publishing at once would put the first records on another
clock than the later ones (stamps jumping back, several records sharing one stamp). So records
are held until the mapping has settled and, when aligning to the camera, until the LED links
the clocks; a run whose LED does not come within `hold_s` stays on the host's clock throughout
(said once). Stamps never go back: a refit of the mapping that would move a stamp before its
predecessor's gives it the predecessor's plus one microsecond.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum
from typing import Generic, TypeVar

import numpy as np

from sds_arduino.clock import DeviceClock, camera_offset_s

Item = TypeVar("Item")
SETTLE_S = 0.5
"""Device time the clock mapping is observed before a session's first record is released [s]:
its lowest delay over many reads gives the offset (the drift follows as records come)."""
HOLD_S = 30.0
"""Device time records wait for the sync LED before the run stays on the host clock [s]."""
MIN_STEP_S = 1e-6
"""Smallest step between two stamps [s]: the device's resolution (micros())."""


class StampClock(Enum):
    """The clock a run's stamps are on, decided once."""

    UNDECIDED = "undecided"
    CAMERA = "camera"
    HOST = "host"


@dataclass(frozen=True)
class Stamped(Generic[Item]):
    """A released item and its stamp [s] on the run's clock."""

    item: Item
    stamp_s: float


class RecordStamper(Generic[Item]):
    """Holds items (records) with their device times until their stamps are known; releases
    them in device order with non-decreasing stamps on one clock (see the module)."""

    def __init__(self, align_to_camera: bool, settle_s: float = SETTLE_S,
                 hold_s: float = HOLD_S) -> None:
        self.align_to_camera = align_to_camera
        self.settle_s = settle_s
        self.hold_s = hold_s
        self.clock_map = DeviceClock()   # this device session's (a reconnect starts one)
        self.clock = StampClock.UNDECIDED if align_to_camera else StampClock.HOST
        self.camera_offset_s = float("nan")   # camera − host time of the same LED switch-on
        # Held items and LED switch-ons: device time [s] and the mapping of its session.
        self._held: deque[tuple[Item, float, DeviceClock]] = deque()
        self._device_led_on: list[tuple[float, DeviceClock]] = []
        self._camera_led_on_s: list[float] = []
        self._first_device_s: float | None = None   # of this session
        self._last_stamp_s = -np.inf

    def add(self, item: Item, device_s: float, received_s: float, led_on: bool = False
            ) -> list[Stamped[Item]]:
        """An item with its device time [s] and the host time it arrived [s] (`led_on`: the
        device switched the sync LED on); the items whose stamps are now known."""
        self.clock_map.observe(device_s, received_s)
        if self._first_device_s is None:
            self._first_device_s = device_s
        if led_on:
            self._device_led_on.append((device_s, self.clock_map))
            self._link()
        self._held.append((item, device_s, self.clock_map))
        return self._release(device_s)

    def camera_led_on(self, camera_s: float) -> list[Stamped[Item]]:
        """The sync LED seen switching on in the video at camera time [s]."""
        self._camera_led_on_s.append(camera_s)
        self._link()
        if not self._held or self._held[-1][2] is not self.clock_map:
            return []
        return self._release(self._held[-1][1])

    def flush(self) -> list[Stamped[Item]]:
        """Every held item (the run ends): on the camera's clock if linked, else the host's."""
        if self.clock is StampClock.UNDECIDED:
            self.clock = StampClock.HOST
        return self._pop_all()

    def _link(self) -> None:
        """The camera's clock against the host's from the LED switch-ons paired in order."""
        pairs = min(len(self._device_led_on), len(self._camera_led_on_s))
        if pairs == 0:
            return
        self.camera_offset_s = camera_offset_s(
            [clock_map.to_host(d) for d, clock_map in self._device_led_on[:pairs]],
            self._camera_led_on_s)
        if self.clock is StampClock.UNDECIDED:
            self.clock = StampClock.CAMERA

    def _release(self, latest_device_s: float) -> list[Stamped[Item]]:
        """Every held item once the mapping has settled and the clock is decided."""
        waited_s = latest_device_s - (self._first_device_s or 0.0)
        if waited_s < self.settle_s:
            return []
        if self.clock is StampClock.UNDECIDED:
            if waited_s < self.hold_s:
                return []
            self.clock = StampClock.HOST
        return self._pop_all()

    def _pop_all(self) -> list[Stamped[Item]]:
        released = []
        if self.clock is StampClock.CAMERA:
            # The mapping may have been refined since the link: the LED's switch-on must map
            # to the camera's own time of it, with the mapping the records get now.
            self._link()
        shift_s = self.camera_offset_s if self.clock is StampClock.CAMERA else 0.0
        while self._held:
            item, device_s, clock_map = self._held.popleft()
            stamp_s = clock_map.to_host(device_s) + shift_s
            stamp_s = max(stamp_s, self._last_stamp_s + MIN_STEP_S)
            self._last_stamp_s = stamp_s
            released.append(Stamped(item, stamp_s))
        return released

    def new_session(self) -> None:
        """A new device session (the port reopened, micros() from 0): its clock mapping is
        learnt anew; held items keep their own session's, the run's clock stays."""
        self.clock_map = DeviceClock()
        self._first_device_s = None
