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

What the motor does on each command is :mod:`~servobus.protocols.lk.sim.handlers`; control
commands map to plant controls as :mod:`~servobus.protocols.lk.sim.control` tabulates; the parameter
commands and the ROM/RAM rules are in :mod:`~servobus.protocols.lk.sim.state`; replies are filled
from the plant by :mod:`~servobus.protocols.lk.sim.replies`; what a C twin shares with the model is
:mod:`~servobus.protocols.lk.sim.twin`.

Errors: :meth:`LkMotor.inject_error` starts a fault condition; its flag latches, the output goes
off and the held command is dropped (protection). 0x9B clears the latched flags whose condition has
ended; flags of a persisting condition stay ("cannot be cleared while the fault persists", spec
§4.2). Control commands are answered but not executed while a flag is latched.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols.lk import (
    DEFAULT_MODEL,
    ErrorState,
    ErrorStateV235,
    LkModel,
    LkReply,
    ParamId,
    ParamValue,
    Revision,
    SettingParam,
    decode_request,
)
from servobus.protocols.lk.codec import reply_frame
from servobus.protocols.lk.ids import MULTI_MOTOR_ID, request_id
from servobus.protocols.lk.model import encoder_counts_per_turn
from servobus.protocols.lk.sim.handlers import handle
from servobus.protocols.lk.sim.intake import ignore_reason, undecodable_reason
from servobus.protocols.lk.sim.replies import status2
from servobus.protocols.lk.sim.state import (
    LK_PLANT_PARAMS,
    LkMemory,
    RunState,
    amps_per_count,
    default_settings,
)
from servobus.protocols.lk.sim.twin import TwinnedMotor
from servobus.sim.device import Emission
from servobus.sim.plant import (
    Brake,
    Control,
    Off,
    Plant,
    PlantParams,
    SpeedControl,
)
from servobus.sim.power import PowerCuts

__all__ = ["DEFAULT_CALIBRATION_S", "DEFAULT_TURNAROUND_S", "LkMotor", "RunState"]

# [001] §1.1: the reply comes "after a period of time (within 0.25 ms)"; [003] states nothing.
DEFAULT_TURNAROUND_S = 200e-6
# [001] §21: 0x18 rotates the motor "for several seconds" and replies when done.
DEFAULT_CALIBRATION_S = 3.0
_ERROR_BITS = {
    Revision.V2_36: 0xFF,
    Revision.V2_35: int(ErrorStateV235.LOW_VOLTAGE | ErrorStateV235.OVER_TEMPERATURE),
}


class LkMotor(TwinnedMotor, PowerCuts):
    """One LK motor on a CAN bus (implements :class:`~servobus.sim.device.Device`).

    On a network that runs the C core (issue 27), the motor gets a C twin (:meth:`core_attach`,
    :mod:`~servobus.protocols.lk.sim.twin`) that answers the control-loop traffic; the attributes C
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
        latched_errors: the error bits latched (0x9A reports them; 0x9B clears those whose fault
            has ended, :meth:`clear_errors`).
        busy_until_s: until when the motor ignores requests (0x18 calibration).

    Raises:
        ValueError: ``motor_id`` outside 1..32, a negative time, or a setting of the wrong scheme.
    """

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
        super().__init__(turnaround_s=turnaround_s, counts_per_turn=per_turn)
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
        self.brake_at_power_up = brake_engaged
        self._counters: Counter[str] = Counter()
        self._conditions = 0  # fault conditions present now (bits of ErrorState)
        # RAM state, set by _power_up (the run state and the held control: TwinnedMotor's).
        self.brake_engaged = brake_engaged
        self.latched_errors = 0
        self.busy_until_s = -math.inf
        self._power_up()

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
        if self.power_back_s is not None and not self.powered(now_s):
            self.plant.advance(now_s)
            return []
        self.plant.advance(now_s)
        self._counters["received"] += 1
        reason = ignore_reason(frame, self.revision, self.motor_id, busy=now_s < self.busy_until_s)
        if reason is not None:
            self._counters[reason] += 1
            return []
        try:
            command = decode_request(frame.arbitration_id, frame.data, model=self.model)
        except ProtocolError:
            reason, code = undecodable_reason(frame, self.revision, self.model.motor_type)
            self._counters[reason] += 1
            reply = None if code is None else self.status2_reply(code)
        else:
            self._counters["accepted"] += 1
            reply = handle(self, command, now_s)
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
        if self.power_back_s is not None:
            self.powered(now_s)
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

    def _power_cut(self, now_s: float) -> None:
        # No supply: the output is off (a brake that engages at power-up engages unpowered); the
        # held command and the turn count are lost at the power-up (reboot).
        self.plant.advance(now_s)
        self.plant.set_control(Brake() if self.brake_at_power_up else Off())

    def _power_changed(self) -> None:
        self._changed()
        self.core_push()  # its C twin stands aside while the power is cut (LkCore.push: not hot)

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
        self.latched_errors |= bits
        self.held = None
        self.plant.set_control(self._control(now_s))
        self.core_push()  # a latched flag: C leaves every frame to Python

    def end_error(self, flags: ErrorState | ErrorStateV235, now_s: float) -> None:
        """The fault condition ``flags`` is gone at ``now_s``; the latched flags wait for 0x9B."""
        self.plant.advance(now_s)
        self._conditions &= ~int(flags)
        self.core_push()

    def clear_errors(self) -> None:
        """0x9B: the latched error bits clear, but for the faults still present (spec §4.2)."""
        self.latched_errors &= self._conditions

    @property
    def error_state(self) -> ErrorState | ErrorStateV235:
        """The latched error flags as the revision reports them (spec §7.1, §7.2)."""
        return (
            ErrorState(self.latched_errors)
            if self.revision is Revision.V2_36
            else ErrorStateV235(self.latched_errors)
        )

    # ---- readings (what the replies carry) ----

    @property
    def multi_turn_deg(self) -> float:
        """0x92's motorAngle: cumulative motor-shaft angle from the zero, encoder-quantised."""
        return self.angles.multi_turn_deg(self.total_counts())

    @property
    def encoder_counts(self) -> int:
        """0x90's encoder: encoderRaw - encoderOffset."""
        return self.angles.encoder(self.total_counts())

    def total_counts(self) -> int:
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
        self.angles.clear_turns(self.total_counts())
        self.state = RunState.ON
        self.held = None
        self.brake_engaged = self.brake_at_power_up
        self.latched_errors = self._conditions
        self.busy_until_s = -math.inf
        self.apply_acceleration()
        self.plant.set_control(self._control(self.plant.now_s))

    def apply_acceleration(self) -> None:
        params = self.plant.params
        limit = self.memory.limits().acceleration_dps2
        self.plant.acceleration_dps2 = (
            limit / params.gear_ratio if limit is not None else params.max_acceleration_dps2
        )

    def _control(self, now_s: float) -> Control:
        if self.brake_engaged:
            return Brake()
        if self.latched_errors or self.state is RunState.OFF or now_s < self.busy_until_s:
            return Off()
        if self.state is RunState.STOPPED:
            return SpeedControl(speed_dps=0.0, max_current_a=self._torque_limit_a())
        return self.held or Off()

    def _torque_limit_a(self) -> float:
        return self.memory.limits().torque_counts * self.amps_per_count

    @property
    def amps_per_count(self) -> float:
        return amps_per_count(self.model.motor_type, self.plant.params)

    def status2_reply(self, code: int) -> LkReply:
        return status2(code, self.model, self.plant, encoder_counts=self.encoder_counts)
