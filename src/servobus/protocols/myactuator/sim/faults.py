"""The simulated MyActuator motor's faults: the error latch and its 0x9A reports, and 0xB3 protection.

Error flags (§7): :meth:`Faults.inject_error` starts a condition (its flags set, the output cut);
:meth:`Faults.clear_error` ends it (auto-recoverable flags clear, latched ones wait for a restart).
While a flag is set and 0x20 index 3 is on, the motor reports 0x9A every 100 ms (the deadline is
``next_report_s``; the reports themselves go out with the streams, in the motor's ``spontaneous``).

0xB3 communication protection: with no frame for this motor within the set time, the output goes off
and the brake locks at that exact time (:meth:`Faults.advance`); the next frame restores it.
With ``trip_echo`` (the default), as V3 drivers are reported to do (2b-t/myactuator_rmd_ros, pull
request 4; in neither manual): the motor sends ``F1 00 00 00 00 00 00 00`` on 0x240+ID at the trip and
every :data:`TRIP_FRAME_PERIOD_S` while it lasts (``comm_trip_frames``), and the next frame for it is
echoed byte for byte and not executed (``comm_echoed``; the motor's ``receive``).
"""

from __future__ import annotations

import math

from servobus.protocols._message import Reply
from servobus.protocols.myactuator import CommunicationTimeoutTripped, ErrorFlags, Revision
from servobus.protocols.myactuator.sim.drive import Drive
from servobus.protocols.myactuator.sim.state import status1
from servobus.sim.plant import Off

__all__ = ["ERROR_REPORT_PERIOD_S", "TRIP_FRAME_PERIOD_S", "Faults"]

#: 0xF1 frames while the 0xB3 protection holds: "repeat this frame every second" (the report above).
TRIP_FRAME_PERIOD_S = 1.0
ERROR_REPORT_PERIOD_S = 0.1  # 0x20 index 3: "every 100 ms" (§4.37)


class Faults(Drive):
    """The fault part of :class:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor`."""

    def inject_error(self, flags: ErrorFlags, now_s: float) -> None:
        """A fault condition starts at ``now_s``: its 0x9A flags set and the output is cut (§7)."""
        self.advance(now_s)
        self.errors.start(ErrorFlags(flags))
        self._counters["errors_injected"] += 1
        self.set_control(Off(), self.run_mode)
        self.update_reports(now_s)

    def clear_error(self, flags: ErrorFlags, now_s: float) -> None:
        """The conditions ``flags`` end at ``now_s``: auto-recoverable flags clear (unless 0x20 index 8
        has switched recovery off, V4.4); latched ones stay until a restart (§4.14)."""
        self.advance(now_s)
        auto = self.ram.error_auto_recovery or self.revision is Revision.V4_3
        self.errors.end(ErrorFlags(flags), auto_recovery=auto)
        self.update_reports(now_s)

    def advance(self, now_s: float) -> None:
        """Bring the plant (and a due 0xB3 trip, at its exact time) up to ``now_s``."""
        self.settle()
        plant = self._plant
        deadline = self.protection_deadline_s()
        if deadline is not None and deadline <= now_s:
            plant.advance(deadline)
            self._trip(deadline)
        plant.advance(now_s)

    def protection_deadline_s(self) -> float | None:
        """When the 0xB3 protection trips if no frame for this motor arrives first (None: off)."""
        if self.ram.comm_timeout_ms <= 0 or self.comm_tripped:
            return None
        return self._last_heard_s + self.ram.comm_timeout_ms / 1000.0

    def _heard(self, now_s: float) -> None:
        self._last_heard_s = now_s
        if self.comm_tripped:
            self.comm_tripped = False
            self._next_trip_frame_s = None
            self._counters["comm_restored"] += 1

    def _trip(self, at_s: float) -> None:
        # §4.33: "cut off the output [and] brake lock".
        self._changed()
        self.comm_tripped = True
        if self.trip_echo:
            self._next_trip_frame_s = at_s  # the first 0xF1 at the trip
        self._counters["comm_timeouts"] += 1
        self.brake_released = False
        self.set_control(Off(), self.run_mode)

    def _echo_unexecuted(self, data: bytes, now_s: float) -> bytes | None:
        """The first frame after a 0xB3 trip: communication is back, the command is not executed,
        its bytes go back as they came (None: nothing is sent)."""
        self._counters["comm_echoed"] += 1
        self._heard(now_s)
        if self.unresponsive:
            self._counters["unanswered"] += 1
            return None
        return data

    def _fault_frames(self, now_s: float, out: list[tuple[float, Reply]]) -> None:
        """Add to ``out`` the 0xF1 trip frame and the 0x9A error report due by ``now_s``."""
        if self._next_trip_frame_s is not None:
            out += self._trip_frames(now_s)
        due = self.next_report_s
        if due is not None and due <= now_s:
            periods = math.floor((now_s - due) / ERROR_REPORT_PERIOD_S + 1e-9) + 1
            self.next_report_s = due + periods * ERROR_REPORT_PERIOD_S
            self._counters["error_reports"] += 1
            out.append((now_s, self.status1_reply()))

    def _trip_frames(self, now_s: float) -> list[tuple[float, Reply]]:
        """The 0xF1 frame due by ``now_s`` while the protection holds (one, however late the poll)."""
        due = self._next_trip_frame_s
        if due is None or due > now_s:
            return []
        periods = math.floor((now_s - due) / TRIP_FRAME_PERIOD_S + 1e-9) + 1
        self._next_trip_frame_s = due + periods * TRIP_FRAME_PERIOD_S
        self._counters["comm_trip_frames"] += 1
        return [(now_s, CommunicationTimeoutTripped())]

    def update_reports(self, now_s: float) -> None:
        self._changed()  # the report deadline, and after a restart the identifiers
        if not (self.errors.flags and self.ram.error_reporting):
            self.next_report_s = None
        elif self.next_report_s is None:
            self.next_report_s = now_s

    def status1_reply(self) -> Reply:
        """The 0x9A reply now (errors, brake, temperature, voltage): what 0x9A and the reports carry."""
        plant = self.plant
        key = (plant.temperature_c, plant.voltage_v, self.brake_released, self.errors.flags)
        if self._status1_reply is None or key != self._status1_key:  # the same poll after poll at rest
            self._status1_key = key
            self._status1_reply = status1(key[0], key[1], brake_released=key[2], errors=key[3])
        return self._status1_reply
