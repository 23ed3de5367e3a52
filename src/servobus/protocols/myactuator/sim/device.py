"""The simulated MyActuator RMD-X motor (protocol V4.3 / V4.4) on a CAN bus: requests in, timed replies out.

Protocol model (spec ``myactuator-v4.md``; [000] = V4.4 manual, [002] = V4.3 manual) over the shared
codec used in reverse: requests are decoded with :func:`~servobus.protocols.myactuator.decode_request`
for the motor's revision, replies are built from the codec's reply classes with values from the
:class:`~servobus.sim.plant.Plant`, and sent ``turnaround_s`` after the request. The RS485 front is
:mod:`~servobus.protocols.myactuator.sim.rs485`; the memory (ROM/RAM, encoder, error latch) and the
reply builders are :mod:`~servobus.protocols.myactuator.sim.state`.

Identifiers (§1.1): 0x140+ID requests and 0x400+ID motion commands of this motor are taken; 0x280
and 0x300 (0x79, V4.3) only while the CAN-ID filter is off (0x20 index 2 value 0), otherwise they
are not received (``filtered``). Replies go to 0x240+ID (0x280 broadcasts too, each motor on its own
id), 0x79 replies to 0x300 as the manual prints them, motion replies to 0x500+ID. Nothing is sent
for 0x76, 0xB4 and 0xB6 (the codec's ``NO_REPLY``).

Ignored frames (nothing sent; a key of :attr:`MyActuatorMotor.counters`): other identifiers
(``ignored_id``), extended or FD frames (``ignored_kind``), commands that only the other revision
has (``other_revision``: 0x72/0x73/0x20 index 8/indexed 0xB5 on V4.3; 0x79/0x90/single-frame 0xB5
on V4.4), anything else that does not decode (``undecodable``).

Command -> plant control (§4.19-§4.26, §5):

=====================  ========================================================================
0xA1 torque            ``CurrentControl(iq)``. It cannot release the brake (§4.19): with the brake
                       locked the shaft stays held (``brake_locked``) until 0x77.
0xA2 speed             ``SpeedControl(speed, limit)``; limit = maxTorque % of ``rated_current_a``
                       when 0 < it < the stall current (the plant's ``max_current_a``), else none.
                       Slew: acceleration index 2 (0 = limited by the current only).
0xA4, 0x72, 0x73       ``PositionControl(angle, maxSpeed or none if 0)``; slew: acceleration index
                       0. The plant has no feed-forward input: 0x72/0x73 behave as 0xA4 (which
                       [000] says 0x72 is in profiled mode); the feed-forward is kept in
                       :attr:`MyActuatorMotor.feedforward_pct`.
0xA6                   ``PositionControl`` to the nearest angle in the given direction (clockwise
                       taken as positive [I]); the reply carries the single-turn encoder (§3.2).
0xA8                   ``PositionControl(measured angle + increment)``.
0xA9                   ``PositionControl(angle, maxSpeed, limit as 0xA2)``.
0x400+ID motion        ``Impedance`` with the command's gains (MIT law, §5.1).
0x80 off               ``Off``: output off; the 0x70 run mode keeps the last loop's value (the
                       manuals define only three modes, §4.27; what 0x80 leaves is unstated [I]).
0x81 stop              hold the present position (``PositionControl``, loop kept, §4.18); no
                       effect while the output is off.
0x77 / 0x78            brake released / locked: a locked brake is the plant's ``Brake`` whatever
                       the command (``has_brake``; without a brake only the flag changes).
=====================  ========================================================================

Every control command but 0xA1 (motion mode included) releases the brake, since the manuals name only
0xA1 as unable to [I]. Control commands (the seven of §0, plus 0xA6 and motion mode [I]: a faulted
drive has its output cut) are answered with the present status but not executed while an error flag
is set (``refused_fault``).

ROM and RAM (§4, §0): 0x31 and 0x43 change the running values at once, 0x32/0x43/0xB3/0x20 and the
zero commands also write the ROM; on V4.4 a ROM save succeeds only while the output is off
("disabled", [000]), otherwise only RAM changes (``rom_write_refused``). The ID (0x20 index 5, 0x79),
the zero (0x63, 0x64), multi-turn clearing/saving (0x20 index 1, 4) and the baud index (0xB4) act
after a restart: :meth:`MyActuatorMotor.reboot` (power cycle) or 0x76, which loads RAM from ROM.

0xB6 active reply ([000]/[002] §2.35/§2.34): "If an active reply command is set, the motor will not
reply after receiving the command." The simulator reads it literally (spec §9 item 18): while any
stream is on, received commands are still executed but never answered (``silenced_by_active_reply``),
motion commands and broadcasts included. Each streamed command has its own timer of
``interval x 10 ms`` (the first frame one interval after the 0xB6 frame; several commands interleave
by their timers; an enabled interval 0 is undefined (§4.36) and does not decode, so that frame is
dropped like any undecodable one); frames go to 0x240+ID (unstated, §1.1).

0xB3 communication-interruption protection: "If the communication is interrupted for more than the
set time, it will cut off the output [and] brake lock. To run again, you need to establish stable
and continuous communication first" ([000] §2.32). When no frame for this motor arrives within the
time, the output goes off and the brake locks (``comm_timeouts``); no error flag is set (none is
named). The next frame for the motor restores communication (``comm_restored``) and is executed;
control commands then run again and release the brake (0xA1 after 0x77). 0 disables it.

0x20 index 3: while an error flag is set the motor sends 0x9A on 0x240+ID every 100 ms, the first
when the error appears (or reporting is switched on).
"""

from __future__ import annotations

import functools
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar, cast

from servobus.core._lib import lib
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import ErrorFlags, IdKind, MotionCommand, Revision, StreamableCommand
from servobus.protocols.myactuator.codec import COMMANDS, decode_standard_request
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    ID_SETTING_ID,
    check_motor_id,
    classify_id,
    motion_reply_id,
    motion_request_id,
    reply_id,
    request_id,
)
from servobus.protocols.myactuator.sim.core import MaCore
from servobus.protocols.myactuator.sim.state import (
    DEFAULT_ENCODER_COUNTS_PER_TURN,
    DEFAULT_MODEL,
    DEFAULT_POLE_PAIRS,
    DEFAULT_VERSION_DATES,
    MYACTUATOR_PLANT_PARAMS,
    EncoderFrame,
    ErrorLatch,
    Readings,
    Settings,
    int32,
    motion_reply,
    single_turn_encoder_reply,
    single_turn_reply,
    single_turn_status_reply,
    status1,
    status3_reply,
    status_reply,
)
from servobus.sim.device import BusLink, Emission, ListeningDevice
from servobus.sim.plant import (
    Brake,
    Control,
    CurrentControl,
    Impedance,
    Off,
    Plant,
    PlantParams,
    PositionControl,
)
from servobus.sim.plant import SpeedControl as PlantSpeedControl

__all__ = ["DEFAULT_TURNAROUND_S", "ERROR_REPORT_PERIOD_S", "MyActuatorMotor", "Stream"]

# The manuals state no turnaround. 200 µs is what a V3 driver's 1 ms-or-faster command loop plus a CAN
# transmit-queue hop gives in practice [I]; the LK sibling states "within 0.25 ms" for its V2.36 drives.
DEFAULT_TURNAROUND_S = 200e-6
ERROR_REPORT_PERIOD_S = 0.1  # 0x20 index 3: "every 100 ms" (§4.37)
STREAM_STEP_S = 0.01  # 0xB6 interval unit: 10 ms/LSB (§4.36, §9 item 29)

_Handler = Callable[[Any, Any, float, bool], "Reply | None"]
#: What the simulated motor does on each command class: the device model registers its handlers here
#: (``@_handles``, or ``@_loop`` for a closed-loop command); the reply's form (none, an echo, a reply)
#: is the command's declaration.
_HANDLERS: dict[type[Command], _Handler] = {}
H = TypeVar("H", bound=Callable[..., Any])
_Loop = Callable[[Any, Any], "tuple[Control, ma.RunMode]"]


def _handles(*classes: type[Command]) -> Callable[[H], H]:
    def register(handler: H) -> H:
        for cls in classes:
            if cls in _HANDLERS:
                raise TypeError(f"two simulator handlers for {cls.__name__}")
            _HANDLERS[cls] = handler
        return handler

    return register


def _loop(*classes: type[Command], releases_brake: bool = True) -> Callable[[_Loop], _Loop]:
    """Register closed-loop commands: ``loop(motor, command)`` gives the plant control and run mode;
    the motor runs it unless a fault is latched, and answers with its status either way."""

    def register(loop: _Loop) -> _Loop:
        def handler(motor: MyActuatorMotor, command: Command, _now_s: float, _rs485: bool) -> Reply:
            return motor._control_command(command, loop, releases_brake=releases_brake)

        _handles(*classes)(handler)
        return loop

    return register


# [I] The manuals define three run modes and no other (§4.27: "has the following 3 states"), so 0x70
# always reports one: after 0x80 (or a fault or comm trip) the last loop's mode stays; at power-up,
# before any control command, the position loop (the manuals' only 0x70 example reads 0x03). In motion
# mode the MIT law ends in a q-axis current reference, so the drive runs its current loop.
RUN_MODE_POWER_UP = ma.RunMode.POSITION_LOOP
_RUN_MODE_MOTION = ma.RunMode.CURRENT_LOOP
_OTHER_REVISION = {Revision.V4_3: Revision.V4_4, Revision.V4_4: Revision.V4_3}


@dataclass(slots=True)
class Stream:
    """One 0xB6 active-reply stream: the next frame is due at ``origin_s + count * interval_s``."""

    interval_s: float
    origin_s: float
    count: int = 1

    @property
    def next_s(self) -> float:
        return self.origin_s + self.count * self.interval_s

    def advance_past(self, now_s: float) -> int:
        """Move the schedule past ``now_s``; return how many due slots were skipped (late poll)."""
        due = math.floor((now_s - self.origin_s) / self.interval_s + 1e-9) + 1
        skipped = max(0, due - self.count - 1)
        self.count = max(self.count + 1, due)
        return skipped


class MyActuatorMotor(ListeningDevice):
    """One MyActuator RMD-X motor on a CAN bus (implements :class:`~servobus.sim.device.Device`).

    Args:
        motor_id: 1..32, stored as the ROM id.
        revision: protocol revision of the firmware (V4.4 = [000], V4.3 = [002]).
        plant_params: the mechanics (default :data:`~.myactuator_state.MYACTUATOR_PLANT_PARAMS`).
        turnaround_s: request received -> reply ready (default :data:`DEFAULT_TURNAROUND_S`).
        model: the 0xB5 model string (7 characters on V4.3, 15 on V4.4).
        version_date: the 0xB2 YYYYMMDD date; default per revision, and it must give ``revision`` under
            ``ma.revision_from_version_date``'s default rule, so a host that picks the revision from 0xB2
            finds the right one.
        motion_scales: motion-mode ranges (default: the revision's, §5.5).
        has_brake: the motor has a holding brake (0x77/0x78 act on the shaft).
        can_id_filter: the ROM state of the CAN-ID filter (default off, so 0x280 works as in the
            manuals' examples).
        rated_current_a: 100 % for the maxTorque / feed-forward percentages (§4.20, §4.24).
        rated_speed_dps: 100 % for 0x72's feed-forward speed.
        encoder_counts_per_turn: rotor encoder resolution.
        pole_pairs: rotor pole pairs (phase currents of 0x9D).
        name: the device name on its bus (default ``myactuator<id>``).
        now_s: simulated time of power-up.

    Attributes:
        rom, ram: the stored and the running parameters (:class:`~.myactuator_state.Settings`).
        control: the commanded plant control (the plant gets ``Brake`` instead while the brake is locked).
        run_mode: the 0x70 value.
        brake_released: the 0x9A brake flag: the brake-release command is in effect.
        comm_tripped: 0xB3 protection has cut the output and no frame has arrived since.
        streams: active 0xB6 streams by command.
        feedforward_pct: the last 0x72/0x73 feed-forward (% of rated speed / current), or None.
        unresponsive: a simulator fault knob: the motor still acts on frames but never transmits.
        counters: frames and events by kind (see the module docstring).

    Raises:
        ValueError: bad id, revision, turnaround, model string, version date or ratings.
    """

    #: The family's C path (csrc/sim_myactuator.c), run by a network that has one (core.py).
    CORE_FAMILY: ClassVar[int] = lib.SB_FAMILY_MYACTUATOR
    _core: MaCore | None = None

    def __init__(
        self,
        motor_id: int,
        *,
        revision: Revision = Revision.V4_4,
        plant_params: PlantParams | None = None,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        model: str = DEFAULT_MODEL,
        version_date: int | None = None,
        motion_scales: ma.MotionScales | None = None,
        has_brake: bool = True,
        can_id_filter: bool = False,
        rated_current_a: float = 10.0,
        rated_speed_dps: float = 720.0,
        encoder_counts_per_turn: int = DEFAULT_ENCODER_COUNTS_PER_TURN,
        pole_pairs: int = DEFAULT_POLE_PAIRS,
        name: str | None = None,
        now_s: float = 0.0,
    ) -> None:
        check_motor_id(motor_id)
        if not isinstance(revision, Revision):
            raise ValueError(f"revision={revision!r} is not a Revision (V4_3, V4_4)")
        if not turnaround_s >= 0:
            raise ValueError(f"turnaround_s={turnaround_s!r} must be >= 0")
        if not (rated_current_a > 0 and rated_speed_dps > 0 and pole_pairs > 0):
            raise ValueError("rated_current_a, rated_speed_dps and pole_pairs must be > 0")
        self.revision = revision
        self.version_date = DEFAULT_VERSION_DATES[revision] if version_date is None else version_date
        if ma.revision_from_version_date(self.version_date) is not revision:
            raise ValueError(
                f"version_date={self.version_date} reads as another revision than {revision.name}"
            )
        self.model = model
        self._model_replies()  # refuse a model string the 0xB5 reply cannot carry, now
        self.turnaround_s = turnaround_s
        self.motion_scales = motion_scales or ma.MOTION_SCALES[revision]
        self.has_brake = has_brake
        self.rated_current_a = rated_current_a
        self.rated_speed_dps = rated_speed_dps
        self.pole_pairs = pole_pairs
        self._name = name or f"myactuator{motor_id}"
        self._plant = Plant(plant_params or MYACTUATOR_PLANT_PARAMS, now_s=now_s)
        self.encoder = EncoderFrame(encoder_counts_per_turn, self.plant.params.gear_ratio)
        self.rom = Settings(motor_id=motor_id, can_id_filter=can_id_filter)
        self.ram = self.rom.copy()
        self.errors = ErrorLatch()
        self.unresponsive = False
        self._counters: Counter[str] = Counter()
        self._decoded: dict[tuple[int, bytes] | None, Command | tuple[Revision, ma.MotionScales]] = {}
        self._status1_key: tuple[float, float, bool, ErrorFlags] | None = None  # the last 0x9A's inputs
        self._status1_reply: Reply | None = None
        self.control: Control = Off()
        self.run_mode = RUN_MODE_POWER_UP
        self.brake_released = False
        self.comm_tripped = False
        self.streams: dict[StreamableCommand, Stream] = {}
        self.feedforward_pct: int | None = None
        self._boot_s = now_s
        self._last_heard_s = now_s
        self._next_report_s: float | None = None
        self._power_up(now_s)

    # ---- Device protocol ----

    @property
    def name(self) -> str:
        """The device name on its bus."""
        return self._name

    @property
    def motor_id(self) -> int:
        """The id the motor answers to now (RAM; a new ROM id acts after a restart)."""
        return self.ram.motor_id

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s``: act on it if it is for this motor, answer once.

        Returns:
            The reply (after ``turnaround_s``), or nothing (not for us, not decodable, no reply by the
            manual, streaming, or unresponsive).
        """
        self.advance(now_s)
        self._counters["received"] += 1
        kind = self._route(frame)
        if kind is None:
            return []
        try:
            command = self._decode(frame.arbitration_id, frame.data)
        except ProtocolError:
            self.count_refused_bytes(frame.data, can_id=frame.arbitration_id)
            return []
        motor_id = self.motor_id  # before a reset could change it
        reply = self.handle(command, now_s)
        if reply is None:
            return []
        if kind is IdKind.MOTION_REQUEST:
            can_id = motion_reply_id(motor_id)
        elif kind is IdKind.ID_SETTING:
            can_id = ID_SETTING_ID  # the 0x79 examples print the reply on 0x300 (§4.38)
        else:
            can_id = _reply_id(motor_id)
        return [Emission(now_s + self.turnaround_s, Frame(arbitration_id=can_id, data=_encode(reply)))]

    def _decode(self, can_id: int, data: bytes) -> Command:
        """The request in a frame: decoded once per distinct frame (a pure function of the bytes, the
        revision and the motion scales; commands are frozen, so one object serves every time)."""
        decoded = self._decoded
        if decoded.get(None) != (self.revision, self.motion_scales):  # changed since: start over
            decoded.clear()
            decoded[None] = (self.revision, self.motion_scales)
        key = (can_id, data)
        command = decoded.get(key)
        if command is None:
            if len(decoded) > _CACHE_SIZE:
                decoded.clear()
                decoded[None] = (self.revision, self.motion_scales)
            command = decoded[key] = ma.decode_request(
                can_id, data, revision=self.revision, motion_scales=self.motion_scales
            )
        assert isinstance(command, Command)
        return command

    def poll(self, now_s: float) -> list[Emission]:
        """Spontaneous frames due by ``now_s``: 0xB6 streams and 0x9A error reports (0x240+ID); also
        trips the 0xB3 protection when its time has passed."""
        return [
            Emission(at, Frame(arbitration_id=reply_id(self.motor_id), data=reply.encode()))
            for at, reply in self.spontaneous(now_s)
        ]

    def next_deadline_s(self) -> float | None:
        """The earliest of: the 0xB3 trip, the next stream frame, the next error report."""
        protection, report = self.protection_deadline_s(), self._next_report_s
        streams = self.streams
        if streams and self._core is not None and self._core.runs_streams():
            streams = {}  # its C twin runs them (sb_ma_next_deadline)
        if not streams and (protection is None or report is None):
            return report if protection is None else protection  # the network asks after every frame
        times = [protection, report]
        times += [stream.next_s for stream in streams.values()]
        found = [t for t in times if t is not None]
        return min(found) if found else None

    # ---- the C twin (core.py; the network calls these) ----

    def core_attach(self, motor: Any, link: BusLink | None) -> None:
        """Run on ``motor`` (an ``sb_simmotor *``): its plant moves there and its C path answers what
        :func:`~.core.c_may_act` allows; ``link`` as :meth:`attach` (see core.py).

        Raises:
            ValueError: already attached to a C twin, or on another network.
        """
        if self._core is not None or (link is not None and self._link not in (None, link)):
            raise ValueError(f"{self!r} is already on a network: remove it from that one first")
        MaCore.attach(self, motor, link)

    def core_detach(self) -> None:
        """Leave the C twin and its network: its changes pulled, the plant back in Python."""
        if self._core is not None:
            self._core.detach()

    def core_push(self) -> None:
        """Write what the C path reads into the twin (the network calls this after each call in)."""
        if self._core is not None:
            self._core.push()

    def listen_ids(self) -> frozenset[int]:
        """0x140+ID, 0x400+ID, 0x280 and 0x300 (filtered or not, it counts them): any other
        identifier is ``ignored_id`` (``ignored_kind`` if extended or FD) whatever it carries."""
        return _listen_ids(self.motor_id)

    def _overhear(self, now_s: float) -> None:
        self.advance(now_s)

    # ---- shared with the RS485 front ----

    def advance(self, now_s: float) -> None:
        """Bring the plant (and a due 0xB3 trip, at its exact time) up to ``now_s``."""
        self.settle()
        plant = self._plant
        deadline = self.protection_deadline_s()
        if deadline is not None and deadline <= now_s:
            plant.advance(deadline)
            self._trip()
        plant.advance(now_s)

    def protection_deadline_s(self) -> float | None:
        """When the 0xB3 protection trips if no frame for this motor arrives first (None: off)."""
        if self.ram.comm_timeout_ms <= 0 or self.comm_tripped:
            return None
        return self._last_heard_s + self.ram.comm_timeout_ms / 1000.0

    def spontaneous(self, now_s: float) -> list[tuple[float, Reply]]:
        """Advance to ``now_s`` and return the stream frames and error reports due, with their times."""
        self.advance(now_s)
        out: list[tuple[float, Reply]] = []
        streams = self.streams
        if streams and self._core is not None and self._core.runs_streams():
            streams = {}  # its C twin runs them (sb_ma_poll)
        for command, stream in streams.items():
            if stream.next_s <= now_s:
                self._counters["stream_skipped"] += stream.advance_past(now_s)
                self._counters["stream_frames"] += 1
                reply = self._execute(_STREAMED[command](), now_s, rs485=False)
                assert reply is not None
                out.append((now_s, reply))
        if self._next_report_s is not None and self._next_report_s <= now_s:
            periods = math.floor((now_s - self._next_report_s) / ERROR_REPORT_PERIOD_S + 1e-9) + 1
            self._next_report_s += periods * ERROR_REPORT_PERIOD_S
            self._counters["error_reports"] += 1
            out.append((now_s, self._status1()))
        if out and self.unresponsive:
            self._counters["unanswered"] += len(out)
            return []
        return out

    def handle(self, command: Command, now_s: float, *, rs485: bool = False) -> Reply | None:
        """Act on a decoded request addressed to this motor; return the reply to send, if any."""
        self._counters["accepted"] += 1
        self._heard(now_s)
        reply = self._execute(command, now_s, rs485=rs485)
        if reply is None:
            return None
        if self.unresponsive:
            self._counters["unanswered"] += 1
            return None
        if self.streams:
            self._counters["silenced_by_active_reply"] += 1
            return None
        self._counters["replied"] += 1
        return reply

    def count_refused_bytes(self, data: bytes, *, can_id: int | None = None, rs485: bool = False) -> None:
        """Count a request this revision refused: ``other_revision`` if the other revision has it."""
        other = _OTHER_REVISION[self.revision]
        try:
            if rs485:
                decode_standard_request(data, other, id_setting_allowed=True)
            else:
                assert can_id is not None
                ma.decode_request(can_id, data, revision=other)
        except ProtocolError:
            self._counters["undecodable"] += 1
        else:
            self._counters["other_revision"] += 1

    # ---- faults and power ----

    def inject_error(self, flags: ErrorFlags, now_s: float) -> None:
        """A fault condition starts at ``now_s``: its 0x9A flags set and the output is cut (§7)."""
        self.advance(now_s)
        self.errors.start(ErrorFlags(flags))
        self._counters["errors_injected"] += 1
        self._set_control(Off(), self.run_mode)
        self._update_reports(now_s)

    def clear_error(self, flags: ErrorFlags, now_s: float) -> None:
        """The conditions ``flags`` end at ``now_s``: auto-recoverable flags clear (unless 0x20 index 8
        has switched recovery off, V4.4); latched ones stay until a restart (§4.14)."""
        self.advance(now_s)
        auto = self.ram.error_auto_recovery or self.revision is Revision.V4_3
        self.errors.end(ErrorFlags(flags), auto_recovery=auto)
        self._update_reports(now_s)

    def reboot(self, now_s: float) -> None:
        """A power cycle at ``now_s``: RAM is loaded from ROM, streams stop, the output is off and the
        brake locked (§4.30), the run time restarts. Physical shaft angle and speed are kept."""
        self.advance(now_s)
        self._counters["reboots"] += 1
        self._power_up(now_s)

    # ---- what the motor reports ----

    @property
    def angle_deg(self) -> float:
        """Output angle from the zero (what 0x92 reports)."""
        return self.encoder.angle_deg(self.plant.motor_position_deg)

    @property
    def enabled(self) -> bool:
        """The output is on (a control command is running): V4.4 refuses ROM saves then."""
        return not isinstance(self.control, Off)

    def readings(self) -> Readings:
        """The measurements a reply would carry now."""
        plant, rotor = self.plant, self.plant.motor_position_deg
        return Readings(
            temperature_c=plant.temperature_c,
            current_a=plant.current_a,
            speed_dps=plant.speed_dps,
            angle_deg=self.encoder.angle_deg(rotor),
            voltage_v=plant.voltage_v,
            rotor_deg=rotor,
            position_counts=self.encoder.position_counts(rotor),
            counts_per_turn=self.encoder.counts_per_turn,
        )

    # ---- internals ----

    def _power_up(self, now_s: float) -> None:
        keep_turns = self.rom.save_multi_turn and not self.rom.clear_multi_turn
        self.rom.clear_multi_turn = False
        self.ram = self.rom.copy()
        self.encoder.offset_counts = self.ram.encoder_offset_counts
        self.encoder.power_up(self.plant.motor_position_deg, keep_turns=keep_turns)
        self.errors.power_up()
        self.brake_released = False
        self.comm_tripped = False
        self.streams = {}
        self.feedforward_pct = None
        self._boot_s = self._last_heard_s = now_s
        self._next_report_s = None
        self._set_control(Off(), RUN_MODE_POWER_UP)
        self._update_reports(now_s)

    def _route(self, frame: Frame) -> IdKind | None:
        if frame.is_extended_id or frame.is_fd:
            self._counters["ignored_kind"] += 1
            return None
        found = _classify_id(frame.arbitration_id)
        kind, motor_id = found if found else (None, None)
        if kind in (IdKind.REQUEST, IdKind.MOTION_REQUEST) and motor_id == self.motor_id:
            return kind
        if kind in (IdKind.BROADCAST, IdKind.ID_SETTING):
            if self.ram.can_id_filter:  # §1.1: with the filter on, 0x280 (and 0x300) are not received
                self._counters["filtered"] += 1
                return None
            return kind
        self._counters["ignored_id"] += 1
        return None

    def _heard(self, now_s: float) -> None:
        self._last_heard_s = now_s
        if self.comm_tripped:
            self.comm_tripped = False
            self._counters["comm_restored"] += 1

    def _trip(self) -> None:
        # §4.33: "cut off the output [and] brake lock".
        self._changed()
        self.comm_tripped = True
        self._counters["comm_timeouts"] += 1
        self.brake_released = False
        self._set_control(Off(), self.run_mode)

    def _update_reports(self, now_s: float) -> None:
        self._changed()  # the report deadline, and after a restart the identifiers
        if not (self.errors.flags and self.ram.error_reporting):
            self._next_report_s = None
        elif self._next_report_s is None:
            self._next_report_s = now_s

    def _set_control(self, control: Control, run_mode: ma.RunMode) -> None:
        self.control = control
        self.run_mode = run_mode
        self._apply_plant()

    def _apply_plant(self) -> None:
        accel = self.ram.acceleration_dps_s
        if isinstance(self.control, PlantSpeedControl):
            slew = accel[ma.AccelIndex.SPEED_ACCELERATION]
        else:
            slew = accel[ma.AccelIndex.POSITION_ACCELERATION]
        self.plant.acceleration_dps2 = slew if slew > 0 else math.inf  # 0: limited by the current only
        locked = self.has_brake and not self.brake_released
        self.plant.set_control(Brake() if locked else self.control)

    def _rom_ok(self) -> bool:
        # [000]: "the parameters can only be saved to ROM successfully when the motor is disabled".
        if self.revision is Revision.V4_4 and self.enabled:
            self._counters["rom_write_refused"] += 1
            return False
        return True

    def _current_limit(self, pct: int | None) -> float | None:
        if pct is None:  # maxTorque 0: force-limit mode off (§4.20)
            return None
        limit = pct / 100.0 * self.rated_current_a
        return limit if 0 < limit < self.plant.params.max_current_a else None

    def _target(self, angle_deg: float) -> float:
        return self.encoder.output_deg_for(angle_deg)

    def _status1(self) -> Reply:
        plant = self.plant
        key = (plant.temperature_c, plant.voltage_v, self.brake_released, self.errors.flags)
        if self._status1_reply is None or key != self._status1_key:  # the same poll after poll at rest
            self._status1_key = key
            self._status1_reply = status1(key[0], key[1], brake_released=key[2], errors=key[3])
        return self._status1_reply

    def _model_replies(self) -> list[Reply]:
        if self.revision is Revision.V4_3:
            return [ma.ModelReply(model=self.model)]
        if len(self.model) > 15:
            raise ValueError(f"model={self.model!r} is longer than 15 characters")
        return [ma.ModelPartReply(part=p, text=self.model[5 * (p - 1) : 5 * p]) for p in (1, 2, 3)]

    def _execute(self, command: Command, now_s: float, *, rs485: bool) -> Reply | None:
        # The handler acts; what comes back follows the command's declaration: nothing for NO_REPLY,
        # an echo of the request for ``[Echo]``, otherwise the reply the handler built.
        cls = type(command)
        handler = _HANDLERS.get(cls)
        if handler is None:
            raise TypeError(f"the simulated motor has no handler for {cls.__name__}")
        reply = handler(self, command, now_s, rs485)
        if cls.NO_REPLY is not None:
            return None
        if cls.REPLY is ma.Echo:
            return ma.Echo(command=cast(ma.MyActuatorCommand[Any], command))
        assert reply is not None, cls
        return reply

    def _control_command(self, command: Command, loop: _Loop, *, releases_brake: bool) -> Reply:
        if self.errors.flags:
            self._counters["refused_fault"] += 1
        else:
            # Every control command but 0xA1 releases the brake: the manuals name only 0xA1 as unable [I].
            self.brake_released = self.brake_released or releases_brake
            self._set_control(*loop(self, command))
        readings = self.readings()
        reply = type(command).REPLY
        if reply is ma.MotionReply:
            return motion_reply(self.motor_id, readings, self.plant.torque_nm, self.motion_scales)
        if reply is ma.SingleTurnStatusReply:
            return single_turn_status_reply(readings)
        assert reply is ma.StatusReply and command.CODE is not None, command
        return status_reply(ma.StatusCommand(command.CODE), readings)

    # ---- closed loops (§4.19-§4.26, §5) ----

    @_loop(ma.TorqueControl, releases_brake=False)
    def _torque(self, command: ma.TorqueControl) -> tuple[Control, ma.RunMode]:
        # §4.19: 0xA1 cannot release the brake; a locked brake keeps the shaft held.
        if self.has_brake and not self.brake_released:
            self._counters["brake_locked"] += 1
        return CurrentControl(current_a=command.current_a), ma.RunMode.CURRENT_LOOP

    @_loop(MotionCommand)
    def _impedance(self, command: MotionCommand) -> tuple[Control, ma.RunMode]:
        p_des_deg = self._target(math.degrees(command.position_rad))
        control = Impedance(
            position_rad=math.radians(p_des_deg),
            velocity_rad_s=command.velocity_rad_s,
            kp=command.kp,
            kd=command.kd,
            torque_ff_nm=command.torque_ff_nm,
        )
        return control, _RUN_MODE_MOTION

    @_loop(ma.SpeedControl)
    def _speed(self, command: ma.SpeedControl) -> tuple[Control, ma.RunMode]:
        limit = self._current_limit(command.max_torque_pct)
        return PlantSpeedControl(speed_dps=command.speed_dps, max_current_a=limit), ma.RunMode.SPEED_LOOP

    @_loop(
        ma.AbsolutePositionControl,
        ma.ForcePositionControl,
        ma.PositionSpeedFeedforward,
        ma.PositionTorqueFeedforward,
    )
    def _absolute(self, command: Any) -> tuple[Control, ma.RunMode]:
        limit = None
        if isinstance(command, ma.ForcePositionControl):
            limit = self._current_limit(command.max_torque_pct)
        if isinstance(command, ma.PositionSpeedFeedforward):
            self.feedforward_pct = command.feedforward_speed_pct
        elif isinstance(command, ma.PositionTorqueFeedforward):
            self.feedforward_pct = command.feedforward_torque_pct
        return self._position(self._target(command.angle_deg), command.max_speed_dps, limit)

    @_loop(ma.IncrementalPositionControl)
    def _incremental(self, command: ma.IncrementalPositionControl) -> tuple[Control, ma.RunMode]:
        return self._position(self.plant.position_deg + command.angle_deg, command.max_speed_dps)

    @_loop(ma.SingleTurnPositionControl)
    def _single_turn(self, command: ma.SingleTurnPositionControl) -> tuple[Control, ma.RunMode]:
        here = self.angle_deg % 360.0
        wanted = command.angle_deg % 360.0
        if command.direction is ma.SpinDirection.CLOCKWISE:
            delta = (wanted - here) % 360.0
        else:
            delta = -((here - wanted) % 360.0)
        return self._position(self.plant.position_deg + delta, command.max_speed_dps)

    @staticmethod
    def _position(
        target_deg: float, max_speed_dps: float | None, limit_a: float | None = None
    ) -> tuple[Control, ma.RunMode]:
        # max_speed_dps None (maxSpeed 0): no limit (§4.21).
        control = PositionControl(position_deg=target_deg, max_speed_dps=max_speed_dps, max_current_a=limit_a)
        return control, ma.RunMode.POSITION_LOOP

    # ---- reads ----

    @_handles(ma.ReadStatus1)
    def _on_status1(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return self._status1()

    @_handles(ma.ReadStatus2)
    def _on_status2(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return status_reply(ma.StatusCommand.READ_STATUS_2, self.readings())

    @_handles(ma.ReadStatus3)
    def _on_status3(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return status3_reply(self.readings(), self.pole_pairs)

    @_handles(ma.ReadMultiTurnAngle)
    def _on_multi_turn_angle(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return ma.MultiTurnAngleReply(angle_deg=int32(self.angle_deg * 100) / 100)

    @_handles(ma.ReadSingleTurnAngle)
    def _on_single_turn_angle(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return single_turn_reply(self.readings(), self.revision)

    @_handles(ma.ReadEncoderPosition, ma.ReadEncoderRaw, ma.ReadEncoderOffset, ma.ReadSingleTurnEncoder)
    def _on_encoder(self, command: Command, _now_s: float, _rs485: bool) -> Reply:
        encoder, rotor = self.encoder, self.plant.motor_position_deg
        if isinstance(command, ma.ReadEncoderPosition):
            return ma.EncoderPositionReply(encoder_counts=int32(encoder.position_counts(rotor)))
        if isinstance(command, ma.ReadEncoderRaw):
            return ma.EncoderRawReply(raw_counts=int32(encoder.raw_counts(rotor)))
        if isinstance(command, ma.ReadEncoderOffset):
            return ma.EncoderOffsetReply(offset_counts=int32(encoder.offset_counts))
        return single_turn_encoder_reply(self.readings(), encoder.raw_counts(rotor), encoder.offset_counts)

    @_handles(ma.ReadPid)
    def _on_read_pid(self, command: ma.ReadPid, _now_s: float, _rs485: bool) -> Reply:
        return ma.PidReply(index=command.index, value=self.ram.pid[command.index])

    @_handles(ma.ReadAcceleration)
    def _on_read_acceleration(self, command: ma.ReadAcceleration, _now_s: float, _rs485: bool) -> Reply:
        value = self.ram.acceleration_dps_s[command.index]
        return ma.AccelerationReply(index=command.index, acceleration_dps_s=value)

    @_handles(ma.ReadRunMode)
    def _on_run_mode(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return ma.RunModeReply(mode=self.run_mode)

    @_handles(ma.ReadRunTime)
    def _on_run_time(self, _command: Command, now_s: float, _rs485: bool) -> Reply:
        return ma.RunTimeReply(run_time_ms=math.floor((now_s - self._boot_s) * 1000 + 1e-6) % (1 << 32))

    @_handles(ma.ReadVersionDate)
    def _on_version_date(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        return ma.VersionDateReply(version_date=self.version_date)

    @_handles(ma.ReadModel, ma.ReadModelPart)
    def _on_model(self, command: Command, _now_s: float, _rs485: bool) -> Reply:
        part = command.part if isinstance(command, ma.ReadModelPart) else 1
        return self._model_replies()[part - 1]

    @_handles(ma.ReadCanId)
    def _on_read_can_id(self, _command: Command, _now_s: float, rs485: bool) -> Reply:
        # The RS485 example puts the id in DATA[7]; the CAN example sends 0x240+ID (§4.38).
        layout = ma.CanIdLayout.DATA7 if rs485 else ma.CanIdLayout.REPLY_IDENTIFIER
        return ma.CanIdReply(motor_id=self.motor_id, layout=layout)

    # ---- writes (their echo or silence follows the declaration) ----

    @_handles(ma.FunctionControl)
    def _function(self, command: ma.FunctionControl, now_s: float, _rs485: bool = False) -> None:
        index, value = command.index, command.value
        saved = self._rom_ok()
        if index is ma.FunctionIndex.CLEAR_MULTI_TURN:
            self.rom.clear_multi_turn = self.rom.clear_multi_turn or saved
        elif index is ma.FunctionIndex.SAVE_MULTI_TURN:
            if saved:
                self.rom.save_multi_turn = bool(value)
        elif index is ma.FunctionIndex.SET_CAN_ID:
            if saved:
                self.rom.motor_id = value
        else:
            attribute, typed = _IMMEDIATE[index]
            for image in (self.ram, self.rom) if saved else (self.ram,):
                setattr(image, attribute, typed(value))
        self._update_reports(now_s)

    @_handles(ma.WritePidRam, ma.WritePidRom)
    def _on_write_pid(self, command: ma.WritePidRam | ma.WritePidRom, _now_s: float, _rs485: bool) -> None:
        self.ram.pid[command.index] = command.value
        if isinstance(command, ma.WritePidRom) and self._rom_ok():
            self.rom.pid[command.index] = command.value

    @_handles(ma.WriteAcceleration)
    def _on_write_acceleration(self, command: ma.WriteAcceleration, _now_s: float, _rs485: bool) -> None:
        accel = 0.0 if command.acceleration_dps_s is None else command.acceleration_dps_s  # None: 0
        self.ram.acceleration_dps_s[command.index] = accel
        if self._rom_ok():
            self.rom.acceleration_dps_s[command.index] = accel
        self._apply_plant()

    @_handles(ma.WriteEncoderZero)
    def _on_encoder_zero(self, command: ma.WriteEncoderZero, _now_s: float, _rs485: bool) -> None:
        if self._rom_ok():  # takes effect after a restart (§4.9)
            self.rom.encoder_offset_counts = command.offset_counts

    @_handles(ma.WriteCurrentPositionAsZero)
    def _on_position_as_zero(self, _command: Command, _now_s: float, _rs485: bool) -> Reply:
        offset = int32(self.encoder.raw_counts(self.plant.motor_position_deg))
        if self._rom_ok():  # takes effect after 0x76 (§4.10)
            self.rom.encoder_offset_counts = offset
        return ma.ZeroOffsetReply(offset_counts=offset)

    @_handles(ma.SetCommTimeout)
    def _on_comm_timeout(self, command: ma.SetCommTimeout, _now_s: float, _rs485: bool) -> None:
        # ROM, and not in [000]'s "only when disabled" list (§8 item 15).
        timeout = 0 if command.timeout_ms is None else command.timeout_ms  # None: protection off
        self.ram.comm_timeout_ms = self.rom.comm_timeout_ms = timeout

    @_handles(ma.SetCanId)
    def _on_set_can_id(self, command: ma.SetCanId, _now_s: float, _rs485: bool) -> None:
        self.rom.motor_id = command.motor_id  # V4.3 only, which has no "only when disabled" rule

    @_handles(ma.SetBaudRate)
    def _on_baud_rate(self, command: ma.SetBaudRate, _now_s: float, _rs485: bool) -> None:
        if self._rom_ok():  # used from the next power-up (§4.34)
            self.rom.baud_index = command.baud_index

    @_handles(ma.SystemReset)
    def _on_reset(self, _command: Command, now_s: float, _rs485: bool) -> None:
        self._counters["resets"] += 1
        self._power_up(now_s)  # §4.28: the program restarts

    @_handles(ma.MotorShutdown)
    def _on_shutdown(self, _command: Command, _now_s: float, _rs485: bool) -> None:
        self._set_control(Off(), self.run_mode)

    @_handles(ma.MotorStop)
    def _on_stop(self, _command: Command, _now_s: float, _rs485: bool) -> None:
        if self.enabled and not self.errors.flags:  # hold where it is; the loop stays (§4.18)
            self._set_control(PositionControl(position_deg=self.plant.position_deg), self.run_mode)

    @_handles(ma.BrakeRelease, ma.BrakeLock)
    def _on_brake(self, command: Command, _now_s: float, _rs485: bool) -> None:
        self.brake_released = isinstance(command, ma.BrakeRelease)
        self._apply_plant()

    @_handles(ma.ActiveReply)
    def _active_reply(self, command: ma.ActiveReply, now_s: float, _rs485: bool = False) -> None:
        if not command.enabled:
            self.streams.pop(command.command, None)
            return
        interval_s = command.interval_code * STREAM_STEP_S  # >= 1 step: enabled streams need one
        self.streams[command.command] = Stream(interval_s=interval_s, origin_s=now_s)

    def __repr__(self) -> str:
        state = "on" if self.enabled else "off"
        errors = self.errors.flags
        return f"MyActuatorMotor(id={self.motor_id}, {self.revision.name}, {state}, errors={errors!r})"


_classify_id = functools.lru_cache(maxsize=None)(classify_id)  # at most 0x800 standard identifiers
_reply_id = functools.lru_cache(maxsize=None)(reply_id)  # a bad id still raises (errors are not cached)


@functools.cache
def _listen_ids(motor_id: int) -> frozenset[int]:
    return frozenset((request_id(motor_id), motion_request_id(motor_id), BROADCAST_ID, ID_SETTING_ID))


# A motor decodes the same few requests (MyActuatorMotor._decode) and encodes the same few replies
# over and over: both are pure, so each is done once per distinct value.
_CACHE_SIZE = 4096


@functools.lru_cache(maxsize=_CACHE_SIZE)
def _encode_cached(reply: Reply) -> bytes:
    return reply.encode()


# Replies whose fields are all integers or scaled to integers: equal replies encode to equal bytes
# (a float32 field would tell 0.0 from -0.0, which compare equal).
_ENCODE_CACHED = frozenset(
    (
        ma.Status1Reply,
        ma.StatusReply,
        ma.Status3Reply,
        ma.SingleTurnStatusReply,
        ma.MultiTurnAngleReply,
        ma.EncoderPositionReply,
    )
)


_ENCODED: dict[int, tuple[Reply, bytes]] = {}  # by id(): the entry keeps its reply (and id) alive


def _encode(reply: Reply) -> bytes:
    if type(reply) not in _ENCODE_CACHED:
        return reply.encode()
    # The status replies come from a memo, so the very same object recurs: look it up by identity
    # first (cheap), by value second.
    found = _ENCODED.get(id(reply))
    if found is not None and found[0] is reply:
        return found[1]
    if len(_ENCODED) >= _CACHE_SIZE:
        _ENCODED.clear()
    data = _encode_cached(reply)
    _ENCODED[id(reply)] = (reply, data)
    return data


# 0x20 indexes that act at once: the Settings attribute and how the 32-bit value is read.
_IMMEDIATE: dict[ma.FunctionIndex, tuple[str, type[bool] | type[int]]] = {
    ma.FunctionIndex.CAN_ID_FILTER: ("can_id_filter", bool),
    ma.FunctionIndex.ERROR_REPORTING: ("error_reporting", bool),
    ma.FunctionIndex.MAX_POSITIVE_ANGLE: ("max_positive_angle", int),
    ma.FunctionIndex.MAX_NEGATIVE_ANGLE: ("max_negative_angle", int),
    ma.FunctionIndex.ERROR_AUTO_RECOVERY: ("error_auto_recovery", bool),
}
# What each streamable command's frames carry: its normal reply (§4.36).
_STREAMED: dict[StreamableCommand, type[Command]] = {
    StreamableCommand(c.CODE): c for c in COMMANDS if c.STREAMABLE and c.CODE is not None
}
