"""The simulated LK-TECH motor (V2.36, and the RMD V2.35 variant): CAN requests in, timed replies out.

Protocol model (spec ``lk-v2.md``; [001] = V2.36, [003] = V2.35) over the shared codec, used in
reverse: requests are decoded with :func:`~servobus.protocols.lk.decode_request` and replies built
from the codec's reply classes, sent on :func:`~servobus.protocols.lk.reply_id` (0x180+ID on V2.36,
0x140+ID on V2.35, spec §1.1) ``turnaround_s`` after the request. The mechanics are a
:class:`~servobus.sim.plant.Plant`; ROM/RAM and the angle frame are in
:mod:`~servobus.protocols.lk.sim.state`.

What the motor ignores (nothing sent, a key of :attr:`LkMotor.counters` counted): frames for other
ids (``ignored_id``), extended or FD frames (``ignored_kind``), commands of the other revision
only (``other_revision``: e.g. 0x8C on V2.35, 0x91 or 0x280 on V2.36), bytes that do not decode
(``undecodable``), anything while calibrating (``busy``). V2.35 replies share the request's
identifier (spec §1.1 rule 5), and the motor cannot tell its own reply from a request: it never
answers it because a CAN node does not receive its own frames (``SimCanNetwork._deliver`` skips the
source), and another motor's reply carries another id. Two motors with one id would answer each
other's replies, as on a real V2.35 bus.

Run states (spec §4.5..§4.7, §9 D15):

* ON (power-up), STOPPED (0x81; [001] 0x95, A30), OFF (0x80, which also drops the held command;
  on V2.36 it also clears the turn count). A STOPPED motor holds zero speed (inferred: the
  manuals say only "stop the motor").
* V2.36: in OFF control commands are answered but not executed (``not_executed_off``) until 0x88;
  after 0x81 a new control command moves the motor (0x88 changes only OFF -> ON).
* V2.35: 0x88 resumes the command held before 0x81; any control command runs the motor.

Control commands map to plant controls as :mod:`~servobus.protocols.lk.sim.control` tabulates; the
parameter commands and the ROM/RAM rules are in :mod:`~servobus.protocols.lk.sim.state`; replies are
filled from the plant by :mod:`~servobus.protocols.lk.sim.replies`.

Errors: :meth:`LkMotor.inject_error` starts a fault condition; its flag latches, the output goes
off and the held command is dropped (protection). 0x9B clears the latched flags whose condition has
ended; flags of a persisting condition stay ("cannot be cleared while the fault persists", spec
§4.2). Control commands are answered but not executed while a flag is latched.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols.lk import (
    DEFAULT_MODEL,
    BrakeAction,
    BrakeState,
    ErrorState,
    ErrorStateV235,
    LkCommand,
    LkModel,
    LkReply,
    ParamId,
    ParamValue,
    Revision,
    SettingParam,
    decode_request,
)
from servobus.protocols.lk.codec import REQUESTS, check_available, reply_frame
from servobus.protocols.lk.ids import MULTI_MOTOR_ID, MULTI_MOTOR_IDS, MULTI_MOTOR_REPLY_CODE, request_id
from servobus.protocols.lk.model import encoder_counts_per_turn
from servobus.protocols.lk.sim.control import CONTROL_COMMANDS, MotionContext, plant_control
from servobus.protocols.lk.sim.core import CORE_FAMILY, LkCore, adopt_plant, release_plant
from servobus.protocols.lk.sim.replies import encoder_reply, single_turn_deg, status1, status2, status3
from servobus.protocols.lk.sim.state import (
    LK_PLANT_PARAMS,
    MEMORY_COMMANDS,
    AngleFrame,
    LkMemory,
    amps_per_count,
    default_settings,
)
from servobus.sim.device import BusLink, Emission, ListeningDevice
from servobus.sim.plant import (
    Brake,
    Control,
    CurrentControl,
    Off,
    Plant,
    PlantParams,
    PositionControl,
    SpeedControl,
)

__all__ = ["DEFAULT_CALIBRATION_S", "DEFAULT_TURNAROUND_S", "LkMotor", "RunState"]

# [001] §1.1: the reply comes "after a period of time (within 0.25 ms)"; [003] states nothing.
DEFAULT_TURNAROUND_S = 200e-6
# [001] §21: 0x18 rotates the motor "for several seconds" and replies when done.
DEFAULT_CALIBRATION_S = 3.0
_H = TypeVar("_H", bound=Callable[..., LkReply])
_ERROR_BITS = {
    Revision.V2_36: 0xFF,
    Revision.V2_35: int(ErrorStateV235.LOW_VOLTAGE | ErrorStateV235.OVER_TEMPERATURE),
}


#: The motor's behaviour per command class: each handler registers the classes it answers, so
#: the command list is the codec's, never a second one here (the declarations test sends each).
_HANDLERS: dict[type, Callable[[LkMotor, Any, float], LkReply]] = {}


def _handles(*classes: type[LkCommand]) -> Callable[[_H], _H]:
    def register(handler: _H) -> _H:
        for cls in classes:
            if cls in _HANDLERS:  # pragma: no cover - a wiring error, caught at import
                raise AssertionError(f"{cls.__name__} has two handlers")
            _HANDLERS[cls] = handler
        return handler

    return register


class RunState(enum.Enum):
    """The motor's run state (spec §4.5..§4.7)."""

    ON = "on"
    STOPPED = "stopped"
    OFF = "off"


class LkMotor(ListeningDevice):
    """One LK motor on a CAN bus (implements :class:`~servobus.sim.device.Device`).

    On a network that runs the C core (issue 27), the motor gets a C twin (:meth:`core_attach`,
    :mod:`~servobus.protocols.lk.sim.core`) that answers the control-loop traffic; the attributes C
    changes (:attr:`state`, :attr:`held`, the counters, the angle frame) are taken back before
    Python reads them, and the knobs C reads (:attr:`unresponsive`, :attr:`turnaround_s`) are
    pushed when they are set.

    Args:
        motor_id: 1..32; requests on 0x140+ID, replies on :func:`~servobus.protocols.lk.reply_id`.
        model: revision, motor type (iq/power units, spec §8.2) and encoder width.
        plant_params: the mechanics (default :data:`~servobus.protocols.lk.sim.state.LK_PLANT_PARAMS`).
        turnaround_s: request received -> reply ready (default 200 µs, within [001]'s 0.25 ms).
        settings: ROM parameters overriding the factory ones (V2.36 :class:`SettingParam`,
            V2.35 :class:`ParamId`).
        encoder_offset_counts: the encoder zero stored in ROM.
        acceleration_dps2: V2.35 power-up acceleration (default: the plant's maximum).
        brake_engaged: the brake state at power-up (V2.36 0x8C).
        calibration_s: how long 0x18 keeps the motor busy before it replies.
        name: the device name on its bus (default ``lk<id>``).
        now_s: simulated time of power-up.

    Attributes:
        unresponsive: a simulator fault knob: the motor still acts on requests but never replies.
        counters: frames by fate (``received``, ``accepted``, ``replied``, ``unanswered`` and the
            ignore reasons of the module docstring, ``not_executed_off``, ``not_executed_fault``,
            ``not_implemented``, ``refused``, ``reboots``).

    Raises:
        ValueError: ``motor_id`` outside 1..32, a negative time, or a setting of the wrong scheme.
    """

    CORE_FAMILY: ClassVar[int] = CORE_FAMILY
    _twin: LkCore | None = None  # the C twin while on a C-core network

    def __init__(
        self,
        motor_id: int,
        *,
        model: LkModel = DEFAULT_MODEL,
        plant_params: PlantParams | None = None,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        settings: Mapping[SettingParam, ParamValue] | Mapping[ParamId, ParamValue] | None = None,
        encoder_offset_counts: int = 0,
        acceleration_dps2: float | None = None,
        brake_engaged: bool = False,
        calibration_s: float = DEFAULT_CALIBRATION_S,
        name: str | None = None,
        now_s: float = 0.0,
    ) -> None:
        request_id(motor_id)  # validates 1..32
        if turnaround_s < 0 or calibration_s < 0:
            raise ValueError(
                f"times must be >= 0 (turnaround_s={turnaround_s}, calibration_s={calibration_s})"
            )
        params = plant_params or LK_PLANT_PARAMS
        per_turn = encoder_counts_per_turn(model.encoder_bits)
        if not 0 <= encoder_offset_counts < per_turn:
            raise ValueError(f"encoder_offset_counts={encoder_offset_counts} is outside 0..{per_turn - 1}")
        self.motor_id = motor_id
        self.model = model
        self.turnaround_s = turnaround_s
        self.calibration_s = calibration_s
        self._name = name or f"lk{motor_id}"
        self._plant = Plant(params, now_s=now_s)
        rom = default_settings(model, motor_id, params)
        for param, value in (settings or {}).items():
            rom[param] = value
        self.memory = LkMemory(
            model,
            rom,
            rom_encoder_offset_counts=encoder_offset_counts,
            rom_acceleration_dps2=acceleration_dps2
            if acceleration_dps2 is not None
            else params.max_acceleration_dps2 * params.gear_ratio,
        )
        self._angles = AngleFrame(per_turn)
        self.brake_at_power_up = brake_engaged
        self.unresponsive = False  # a fault knob, not motor RAM: a reboot keeps it
        self._counters: Counter[str] = Counter()
        self._conditions = 0  # fault conditions present now (bits of ErrorState)
        # RAM state, set by _power_up.
        self._state = RunState.ON
        self._held: Control | None = None
        self.brake_engaged = brake_engaged
        self._latched = 0
        self._busy_until_s = -math.inf
        self._power_up()

    # ---- what the C twin changes or reads (issue 27: see the class docstring) ----

    @property
    def state(self) -> RunState:
        """The run state (spec §4.5..§4.7)."""
        if self._twin is not None:
            self._twin.pull()
        return self._state

    @state.setter
    def state(self, value: RunState) -> None:
        if self._twin is not None:
            self._twin.pull()
        self._state = value

    @property
    def held(self) -> Control | None:
        """The control command held (run while ON; 0x80 and protection drop it)."""
        if self._twin is not None:
            self._twin.pull()
        return self._held

    @held.setter
    def held(self, value: Control | None) -> None:
        if self._twin is not None:
            self._twin.pull()
        self._held = value

    @property
    def angles(self) -> AngleFrame:
        """The encoder counts' zero points (V2.36 0x80 moves the multi-turn origin, in C too)."""
        if self._twin is not None:
            self._twin.pull()
        return self._angles

    @property
    def unresponsive(self) -> bool:
        """A simulator fault knob: the motor still acts on requests but never replies."""
        return self._unresponsive

    @unresponsive.setter
    def unresponsive(self, value: bool) -> None:
        self._unresponsive = value
        self.core_push()

    @property
    def turnaround_s(self) -> float:
        """Request received -> reply ready."""
        return self._turnaround_s

    @turnaround_s.setter
    def turnaround_s(self, value: float) -> None:
        self._turnaround_s = value
        self.core_push()

    def core_attach(self, motor: Any, link: BusLink | None) -> None:
        """Take the C twin ``motor`` (a zeroed ``sb_simmotor *``) and ``link`` from a C-core network:
        the plant moves into ``motor.plant`` and C answers the control-loop traffic from now on."""
        if link is not None and link is not self._link:
            self.attach(link)
        self.settle()
        self._plant = adopt_plant(self._plant, motor)
        self._twin = LkCore(self, motor)
        self._twin.push()

    def core_detach(self) -> None:
        """Leave the C-core network: take C's last changes and the plant back into Python."""
        twin = self._twin
        if twin is None:
            return
        self.settle()
        self._twin = None
        self._plant = release_plant(self._plant)
        if self._link is not None:
            self.attach(None)

    def core_push(self) -> None:
        """Write into the C twin everything it reads (nothing without one)."""
        if self._twin is not None:
            self._twin.push()

    def settle(self) -> None:
        """Take what the C twin changed, then settle up with the network (ListeningDevice)."""
        if self._twin is not None:
            self._twin.pull()
        super().settle()

    # ---- Device protocol ----

    @property
    def name(self) -> str:
        """The device name on its bus."""
        return self._name

    @property
    def revision(self) -> Revision:
        """The protocol revision the motor speaks."""
        return self.model.revision

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s``: act on it if it is ours and answer once.

        Returns:
            The reply (0x280: this motor's reply) ready ``turnaround_s`` later (0x18: after the
            calibration), or nothing (ignored, or :attr:`unresponsive`).
        """
        self.plant.advance(now_s)
        self._counters["received"] += 1
        reason = self._ignore_reason(frame, now_s)
        if reason is not None:
            self._counters[reason] += 1
            return []
        try:
            command = decode_request(frame.arbitration_id, frame.data, model=self.model)
        except ProtocolError:
            reply = self._undecodable(frame)
        else:
            self._counters["accepted"] += 1
            reply = self._handle(command, now_s)
        self.plant.set_control(self._control(now_s))
        if reply is None:
            return []
        if self.unresponsive:
            self._counters["unanswered"] += 1
            return []
        self._counters["replied"] += 1
        delay = self.calibration_s if isinstance(reply, lk.CalibrationReply) else self.turnaround_s
        return [Emission(now_s + delay, reply_frame(reply, motor_id=self.motor_id, model=self.model))]

    def poll(self, now_s: float) -> list[Emission]:
        """Nothing: an LK motor only answers (no active reports in either manual)."""
        self.plant.advance(now_s)
        return []

    def next_deadline_s(self) -> float | None:
        """None: no spontaneous frames."""
        return None

    def listen_ids(self) -> frozenset[int]:
        """0x140+ID and 0x280: any other identifier is ``ignored_id`` (``ignored_kind`` if extended
        or FD) whatever it carries."""
        return frozenset((request_id(self.motor_id), MULTI_MOTOR_ID))

    # ---- faults and power ----

    def reboot(self, now_s: float) -> None:
        """A power cycle at ``now_s``: RAM <- ROM, the turn count is lost, the motor is ON and idle.

        V2.36: a Driver ID saved with 0x44 becomes the motor id. Fault conditions still present
        latch again at power-up. A reply already handed to the bus still goes out.
        """
        self.plant.advance(now_s)
        self._counters["reboots"] += 1
        self._power_up()
        self.core_push()

    def inject_error(
        self, flags: ErrorState | ErrorStateV235, now_s: float, *, persistent: bool = True
    ) -> None:
        """A fault condition starts at ``now_s`` (over-voltage, over-temperature, ...).

        The flags latch and the protection trips: output off, held command dropped. A transient
        (``persistent=False``) condition is over at once; a persistent one lasts until
        :meth:`end_error`. Either way the flags stay set until 0x9B clears them.

        Raises:
            ValueError: a flag the motor's revision does not define (V2.35: bits 0 and 3 only).
        """
        bits = int(flags)
        if bits & ~_ERROR_BITS[self.revision]:
            raise ValueError(f"flags=0x{bits:02X} has bits {self.revision.name} does not define")
        self.plant.advance(now_s)
        if persistent:
            self._conditions |= bits
        self._latched |= bits
        self.held = None
        self.plant.set_control(self._control(now_s))
        self.core_push()  # a latched flag: C leaves every frame to Python

    def end_error(self, flags: ErrorState | ErrorStateV235, now_s: float) -> None:
        """The fault condition ``flags`` is gone at ``now_s``; the latched flags wait for 0x9B."""
        self.plant.advance(now_s)
        self._conditions &= ~int(flags)
        self.core_push()

    @property
    def error_state(self) -> ErrorState | ErrorStateV235:
        """The latched error flags as the revision reports them (spec §7.1, §7.2)."""
        return ErrorState(self._latched) if self.revision is Revision.V2_36 else ErrorStateV235(self._latched)

    # ---- readings (what the replies carry) ----

    @property
    def multi_turn_deg(self) -> float:
        """0x92's motorAngle: cumulative motor-shaft angle from the zero, encoder-quantised."""
        return self.angles.multi_turn_deg(self._total())

    @property
    def encoder_counts(self) -> int:
        """0x90's encoder: encoderRaw - encoderOffset."""
        return self.angles.encoder(self._total())

    def _total(self) -> int:
        return self.angles.total(self.plant.motor_position_deg)

    # ---- power-up and the effective control ----

    def _power_up(self) -> None:
        self._changed()  # a saved driver id becomes the motor id (V2.36)
        memory = self.memory
        memory.power_up()
        if self.revision is Revision.V2_36:
            driver_id = memory.rom[SettingParam.DRIVER_ID]
            if isinstance(driver_id, int) and 1 <= driver_id <= 32:  # 0 is not addressable (A29)
                self.motor_id = driver_id
        self.angles.offset = memory.encoder_offset_counts
        self.angles.clear_turns(self._total())
        self.state = RunState.ON
        self.held = None
        self.brake_engaged = self.brake_at_power_up
        self._latched = self._conditions
        self._busy_until_s = -math.inf
        self._apply_acceleration()
        self.plant.set_control(self._control(self.plant.now_s))

    def _apply_acceleration(self) -> None:
        params = self.plant.params
        limit = self.memory.limits().acceleration_dps2
        self.plant.acceleration_dps2 = (
            limit / params.gear_ratio if limit is not None else params.max_acceleration_dps2
        )

    def _control(self, now_s: float) -> Control:
        if self.brake_engaged:
            return Brake()
        if self._latched or self.state is RunState.OFF or now_s < self._busy_until_s:
            return Off()
        if self.state is RunState.STOPPED:
            return SpeedControl(speed_dps=0.0, max_current_a=self._torque_limit_a())
        return self.held or Off()

    def _torque_limit_a(self) -> float:
        return self.memory.limits().torque_counts * self._amps_per_count

    @property
    def _amps_per_count(self) -> float:
        return amps_per_count(self.model.motor_type, self.plant.params)

    # ---- frame filtering ----

    def _ignore_reason(self, frame: Frame, now_s: float) -> str | None:
        if frame.is_extended_id or frame.is_fd:
            return "ignored_kind"
        if frame.arbitration_id == MULTI_MOTOR_ID:
            if self.revision not in lk.MultiMotorTorque.REVISIONS:
                return "other_revision"
            if self.motor_id not in MULTI_MOTOR_IDS:
                return "ignored_id"
        elif frame.arbitration_id != request_id(self.motor_id):
            return "ignored_id"
        if now_s < self._busy_until_s:
            return "busy"
        return None

    def _undecodable(self, frame: Frame) -> LkReply | None:
        data = frame.data
        code = data[0] if data and frame.arbitration_id != MULTI_MOTOR_ID else None
        ours = REQUESTS[self.revision]
        if code is not None and code not in ours and any(code in REQUESTS[r] for r in Revision):
            self._counters["other_revision"] += 1
            return None
        if code is not None and code in ours and len(data) == 8:
            # 0xA1 is "only implemented on MF, MH, MG" ([001] §10; the codec has no iq for MS on
            # either revision). The motor still answers (one reply per request, spec §1.1), idle.
            allowed = ours[code].MOTOR_TYPES.get(self.revision)
            if allowed is not None and self.model.motor_type not in allowed:
                self._counters["not_implemented"] += 1
                return self._status2(code)
        self._counters["undecodable"] += 1
        return None

    # ---- commands ----

    def _handle(self, command: LkCommand, now_s: float) -> LkReply:
        handler = _HANDLERS.get(type(command))
        if handler is None:  # pragma: no cover - the declarations test sends every command class
            raise AssertionError(f"no handler for {type(command).__name__}")
        return handler(self, command, now_s)

    @_handles(lk.ReadStatus1, lk.ClearErrors)
    def _status1(self, command: LkCommand, now_s: float) -> LkReply:
        if isinstance(command, lk.ClearErrors):
            self._latched &= self._conditions  # spec §4.2: persisting faults stay set
        code = type(command).CODE
        assert code is not None
        return status1(code, self.model, self.plant, off=self.state is RunState.OFF, errors=self._latched)

    @_handles(lk.ReadStatus2)
    def _read_status2(self, command: LkCommand, now_s: float) -> LkReply:
        return self._status2(0x9C)

    @_handles(lk.ReadStatus3)
    def _read_status3(self, command: LkCommand, now_s: float) -> LkReply:
        return status3(self.model, self.plant)

    @_handles(lk.MotorOff)
    def _off(self, command: LkCommand, now_s: float) -> LkReply:
        self.state, self.held = RunState.OFF, None
        if self.revision is Revision.V2_36:
            self.angles.clear_turns(self._total())  # [001] §5: "clear the number of turns"
        return lk.EchoReply(command=0x80)

    @_handles(lk.MotorStop)
    def _stop(self, command: LkCommand, now_s: float) -> LkReply:
        if self.state is RunState.ON:
            self.state = RunState.STOPPED
        return lk.EchoReply(command=0x81)

    @_handles(lk.MotorRun)
    def _run(self, command: LkCommand, now_s: float) -> LkReply:
        # [001]: OFF -> ON only; [003]: resume the mode held before 0x81 (or after 0x80: idle).
        if self.state is RunState.OFF or self.revision is Revision.V2_35:
            self.state = RunState.ON
        return lk.EchoReply(command=0x88)

    @_handles(lk.SetZeroRam)
    def _zero_ram(self, command: LkCommand, now_s: float) -> LkReply:
        self.angles.zero_here(self._total())
        if self.revision is Revision.V2_36 and self.state is RunState.ON:
            self.state = RunState.STOPPED  # [001] §25, A30
        return lk.EchoReply(command=0x95)

    @_handles(lk.BrakeControl)
    def _brake(self, command: lk.BrakeControl, now_s: float) -> LkReply:
        if command.action is not BrakeAction.READ:
            self.brake_engaged = command.action is BrakeAction.ENGAGE
        return lk.BrakeReply(state=BrakeState.ENGAGED if self.brake_engaged else BrakeState.RELEASED)

    @_handles(lk.MultiMotorTorque)
    def _multi_motor(self, command: lk.MultiMotorTorque, now_s: float) -> LkReply:
        slot = self.motor_id - 1
        if command.currents_a is not None:
            current = command.currents_a[slot]
        else:
            current = (command.iq_counts or (0, 0, 0, 0))[slot] * self._amps_per_count
        self._execute(command, CurrentControl(current_a=current))
        return self._status2(MULTI_MOTOR_REPLY_CODE)

    @_handles(*CONTROL_COMMANDS)
    def _set_point(self, command: LkCommand, now_s: float) -> LkReply:
        code = type(command).CODE
        assert code is not None
        self._execute(command, plant_control(command, self._motion_context()))
        return self._status2(code)

    @_handles(lk.CalibrateEncoder)
    def _calibrate(self, command: LkCommand, now_s: float) -> LkReply:
        # [001] §21: busy for several seconds, then the result (ROM). The sim does not rotate the
        # shaft; the calibration always succeeds.
        self._busy_until_s = now_s + self.calibration_s
        self.held = None
        raw = self.angles.raw(self._total())
        return lk.CalibrationReply(align_value=raw, align_ratio=1000, align_state=lk.AlignState.SUCCESS)

    @_handles(lk.ReadEncoder)
    def _read_encoder(self, command: LkCommand, now_s: float) -> LkReply:
        return encoder_reply(self.model, self.angles, self._total())

    @_handles(lk.SetZeroRom)
    def _zero_rom(self, command: LkCommand, now_s: float) -> LkReply:
        # spec §4.22: ROM only, "needs to be powered on again before it can take effect".
        offset = self.memory.rom_encoder_offset_counts = self.angles.raw(self._total())
        return lk.EncoderOffsetReply(command=0x19, encoder_bits=self.model.encoder_bits, offset_counts=offset)

    @_handles(lk.WriteEncoderOffset)
    def _write_offset(self, command: lk.WriteEncoderOffset, now_s: float) -> LkReply:
        self.memory.rom_encoder_offset_counts = command.offset_counts  # A21: read as RAM and ROM
        self.angles.set_offset(command.offset_counts)
        return lk.EncoderOffsetReply(
            command=0x91, encoder_bits=self.model.encoder_bits, offset_counts=command.offset_counts
        )

    @_handles(lk.ReadMultiTurnAngle)
    def _read_multi_turn(self, command: LkCommand, now_s: float) -> LkReply:
        return lk.MultiTurnAngleReply(angle_deg=self.multi_turn_deg)

    @_handles(lk.ReadSingleTurnAngle)
    def _read_single_turn(self, command: LkCommand, now_s: float) -> LkReply:
        angle = single_turn_deg(self.revision, self.plant.params.gear_ratio, self.multi_turn_deg)
        if self.revision is Revision.V2_36:
            return lk.SingleTurnAngleReply(angle_deg=angle)
        return lk.SingleTurnAngleReplyV235(angle_deg=angle)

    @_handles(*MEMORY_COMMANDS)
    def _parameter(self, command: LkCommand, now_s: float) -> LkReply:
        reply = self.memory.answer(command)
        assert reply is not None  # registered for MEMORY_COMMANDS only
        if isinstance(reply, lk.ParamWriteReply) and not reply.ok:
            self._counters["refused"] += 1
        self._apply_acceleration()  # 0xC1, 0x42/0x44 (V2.35) and 0x34 may change it
        return reply

    def _execute(self, command: LkCommand, control: Control) -> None:
        try:
            check_available(command, model=self.model)
        except ValueError:
            self._counters["not_implemented"] += 1  # [001] 0xA0 on MF/MH/MG: "invalid"
            return
        if self._latched:
            self._counters["not_executed_fault"] += 1
            return
        if self.revision is Revision.V2_36 and self.state is RunState.OFF:
            self._counters["not_executed_off"] += 1  # [001] §5: replies, "will not perform the action"
            return
        self.state, self.held = RunState.ON, control

    def _status2(self, code: int) -> LkReply:
        return status2(code, self.model, self.plant, encoder_counts=self.encoder_counts)

    def _motion_context(self) -> MotionContext:
        held = self.held if self.state is RunState.ON else None
        return MotionContext(
            revision=self.revision,
            gear_ratio=self.plant.params.gear_ratio,
            amps_per_count=self._amps_per_count,
            limits=self.memory.limits(),
            multi_turn_deg=self.multi_turn_deg,
            origin_deg=self.angles.origin_deg(),
            position_deg=self.plant.position_deg,
            held_target_deg=held.position_deg if isinstance(held, PositionControl) else None,
        )
