"""The simulated hollow-series motor: classic CAN (normal/extended) or CAN FD, one reply per request.

Protocol model (hollow.md §3-§7, §13) on top of the shared codec, plant model apart:

* The motor accepts only frames whose identifier equals its ``motor_id`` and whose kind its
  interface takes: classic frames when not ``fd_enabled``; 16-byte CAN FD frames (and the PI
  multiplier frames, classic or FD, A17) when ``fd_enabled``. Everything else is ignored, as a real
  motor does (§3 "pure slave"), and counted in :attr:`HollowMotor.counters`.
* Every accepted frame is answered once (A37), ``turnaround_s`` after it was received, on the host
  id: 6 bytes in normal mode, 8 in extended mode, 16 FD bytes in CAN FD mode. The values are the
  plant's measurements when the request was processed (§4.4: "reported values are always real-time
  measurements").

Mode -> plant mapping (§4.4 "meaning of the fields in each mode"; CAN FD by analogy, §7.2):

==========  =================================================================================
torque      :class:`~servobus.sim.plant.CurrentControl` at T (the target current)
speed       :class:`~servobus.sim.plant.SpeedControl` at V, current limited to \\|T\\|
position    :class:`~servobus.sim.plant.PositionControl` to P (from the zero), speed limited to
            \\|V\\|, current limited to \\|T\\|: the manual's "position-velocity-torque triple closed
            loop" is a cascade with those two limits. KP/KD are stored (:attr:`HollowMotor.setpoint`)
            but do not shape the response: the plant's position loop has one bandwidth
            (``PlantParams.position_bandwidth_hz``) and no per-command gains.
stopped     :class:`~servobus.sim.plant.Off` (FD / Run Cmd 0: "no output power, free")
==========  =================================================================================

Start without a setpoint: the manual says the motion is undefined (§4.1). The simulator chooses
the safe reading: the motor is enabled but commands zero current (it holds no position and moves
only if something else moves it) and counts ``start_without_setpoint``. The exception is the one
the manual defines: FC in extended position mode locks at the present position (§5.2), with the
last setpoint's limits or, if there is none, the model's full scales.

What each request does to the motor's state is :mod:`~servobus.protocols.hollow.sim.behaviour`.
On a C network (:class:`~servobus.sim.corenet.CoreCanNetwork`) the set-point frames and their replies
run in C (csrc/sim_hollow.c, glue in :mod:`~servobus.protocols.hollow.sim.core`); this model is
their reference and handles everything else.

Faults: the hollow replies carry no error or fault field (§4.5, §5.3, §7.3; the manual describes
no error state at all), so there is nothing to inject beyond :meth:`HollowMotor.reboot` and
:attr:`HollowMotor.unresponsive`.
"""

from __future__ import annotations

import random
from collections import Counter

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols.hollow import (
    DEFAULT_HOST_ID,
    DEFAULT_MODEL,
    CanMode,
    CanModeSwitch,
    ControlMode,
    ExtendedReply,
    FdReply,
    HollowModel,
    HollowReply,
    NormalReply,
    PiGain,
)
from servobus.protocols.hollow.codec import decode_request_frame, reply_frame
from servobus.protocols.hollow.ids import check_host_id, check_motor_id
from servobus.protocols.hollow.replies import EXTENDED_POSITION_LIMITS_DEG
from servobus.protocols.hollow.sim.behaviour import (
    DPS_PER_RAD_S,
    DPS_PER_RPM,
    HeldSetpoint,
    apply,
    implemented,
)
from servobus.protocols.hollow.sim.core import HollowCore
from servobus.sim.device import Emission
from servobus.sim.plant import (
    Control,
    CurrentControl,
    Off,
    Plant,
    PlantParams,
    PositionControl,
    SpeedControl,
)

__all__ = [
    "DEFAULT_FD_CURRENT_A_PER_COUNT",
    "DEFAULT_TURNAROUND_S",
    "HOLLOW_PLANT_PARAMS",
    "HeldSetpoint",
    "HollowMotor",
    "implemented",
]

# §3 / A13: "from receipt of commands to the answer the module requires 500 µs"; §3's simulator
# advice: "a fixed 500 µs is a good default".
DEFAULT_TURNAROUND_S = 500e-6
# A27: the CAN FD current field is a raw int16 with no stated unit. The simulator reads it as
# milliamperes [I]: ±32.767 A covers every hollow model, and the one printed reply (H17, raw 8 at
# rest) is then a plausible idle current.
DEFAULT_FD_CURRENT_A_PER_COUNT = 0.001
# A small direct-drive hollow joint motor [I]: no gear (the manual's zero is single-turn and
# "gearbox offsets are the user's responsibility", §2.5), a 4 A current limit matching the
# default model's current full scale (A8), a light rotor.
HOLLOW_PLANT_PARAMS = PlantParams(
    inertia_kgm2=2e-4,
    viscous_friction_nm_s_per_rad=0.002,
    torque_constant_nm_per_a=0.25,
    gear_ratio=1.0,
    max_current_a=4.0,
    max_speed_dps=3600.0,
    max_acceleration_dps2=36000.0,
    position_bandwidth_hz=8.0,
    winding_resistance_ohm=1.0,
    thermal_resistance_c_per_w=3.0,
    thermal_capacity_j_per_c=30.0,
)

_TEMPERATURE_LIMITS_C = (-125, 125)  # §7.3
_INT16 = (-(1 << 15), (1 << 15) - 1)


class HollowMotor(HollowCore):
    """One hollow-series motor on a CAN or CAN FD bus (implements :class:`~servobus.sim.device.Device`).

    Args:
        motor_id: console *g*: the CAN id it accepts (0..100).
        host_id: console *h*: the id it replies on (default 100).
        model: the scales of the motor model (speed/current full scales, Pmax, pole pairs).
        fd_enabled: console *f*: CAN FD (True) or classic CAN (False), never both (§1).
        control_mode: console *p*: the control mode at power-up (§2.3).
        plant_params: the mechanics (default :data:`HOLLOW_PLANT_PARAMS`).
        turnaround_s: delay from a request's reception to its reply being ready (≤ 500 µs, §3).
        turnaround_jitter_s: if > 0, each reply is ready a seeded-random 0..jitter earlier than
            ``turnaround_s`` (a real firmware's loop phase), so the delay stays within the manual's
            bound when ``turnaround_s`` is 500 µs.
        seed: seed of the jitter generator (same seed, same delays).
        fd_current_a_per_count: amperes per count of the CAN FD Cur field (unit not stated, A27).
        console_zero_deg: the console-stored zero, in the plant's angle frame (§2.5).
        name: the device name on its bus (default ``hollow<id>``).
        now_s: simulated time of power-up.

    Raises:
        ValueError: an id out of range, or a negative turnaround / jitter larger than it.
    """

    MISSED_ODD = "ignored_id"  # the motor checks the identifier before the kind

    def __init__(
        self,
        motor_id: int,
        *,
        host_id: int = DEFAULT_HOST_ID,
        model: HollowModel = DEFAULT_MODEL,
        fd_enabled: bool = False,
        control_mode: ControlMode = ControlMode.POSITION,
        plant_params: PlantParams | None = None,
        turnaround_s: float = DEFAULT_TURNAROUND_S,
        turnaround_jitter_s: float = 0.0,
        seed: int = 0,
        fd_current_a_per_count: float = DEFAULT_FD_CURRENT_A_PER_COUNT,
        console_zero_deg: float = 0.0,
        name: str | None = None,
        now_s: float = 0.0,
    ) -> None:
        check_motor_id(motor_id)
        check_host_id(host_id)
        if not 0.0 <= turnaround_jitter_s <= turnaround_s:
            raise ValueError(
                f"need 0 <= turnaround_jitter_s <= turnaround_s "
                f"(turnaround_s={turnaround_s}, turnaround_jitter_s={turnaround_jitter_s})"
            )
        if not fd_current_a_per_count > 0:
            raise ValueError(f"fd_current_a_per_count={fd_current_a_per_count!r} must be > 0")
        super().__init__(
            motor_id=motor_id,
            host_id=host_id,
            model=model,
            fd_enabled=fd_enabled,
            turnaround_s=turnaround_s,
            turnaround_jitter_s=turnaround_jitter_s,
            fd_current_a_per_count=fd_current_a_per_count,
        )
        self.power_up_mode = ControlMode(control_mode)
        self.console_zero_deg = console_zero_deg
        self._name = name or f"hollow{motor_id}"
        self._rng = random.Random(seed)
        self._plant = Plant(plant_params or HOLLOW_PLANT_PARAMS, now_s=now_s)
        # A fault knob of the simulator, not motor RAM: a reboot leaves it as it is.
        self.unresponsive = False
        self._counters: Counter[str] = Counter()
        # RAM state (§13), set by _power_up.
        self.enabled = False
        self.can_mode = CanMode.NORMAL
        self.ctrl_mode = self.power_up_mode
        self.setpoint: HeldSetpoint | None = None
        self.zero_offset_deg = 0.0
        self.pi_multipliers: dict[PiGain, float] = {}
        self._power_up()

    # ---- Device protocol ----

    @property
    def name(self) -> str:
        """The device name on its bus."""
        return self._name

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s``: apply it if it is ours, and answer once.

        Args:
            frame: the frame, as every node on the wire sees it.
            now_s: when its transmission ended.

        Returns:
            One reply on the host id, or nothing (not ours, not decodable, or unresponsive).
        """
        if self.power_back_s is not None and not self.powered(now_s):
            self.plant.advance(now_s)
            return []
        self.plant.advance(now_s)
        self._counters["received"] += 1
        if frame.arbitration_id != self.motor_id:
            self._counters["ignored_id"] += 1
            return []
        if not self._right_kind(frame):
            self._counters["ignored_kind"] += 1
            return []
        try:
            command = decode_request_frame(frame, model=self.model, can_mode=self.can_mode)
        except ProtocolError:
            self._counters["undecodable"] += 1
            return []
        if isinstance(command, CanModeSwitch) and self.fd_enabled:
            # §5: normal/extended are classic-CAN modes; a CAN FD motor has nothing to switch.
            self._counters["ignored_kind"] += 1
            return []
        self._counters["accepted"] += 1
        apply(self, command)
        self.plant.set_control(self._control())
        if self.unresponsive:
            self._counters["unanswered"] += 1
            return []
        self._counters["replied"] += 1
        return [Emission(now_s + self._turnaround(), reply_frame(self.host_id, self.status_reply()))]

    def poll(self, now_s: float) -> list[Emission]:
        """Nothing: the motor never transmits on its own (§3, "pure slave")."""
        if self.power_back_s is not None:
            self.powered(now_s)
        self.plant.advance(now_s)
        return []

    def next_deadline_s(self) -> float | None:
        """None: no spontaneous frames."""
        return None

    def listen_ids(self) -> frozenset[int]:
        """Its own id (any kind): any other identifier is ``ignored_id``, which the motor checks first."""
        return frozenset((self.motor_id,))

    # ---- faults and power ----

    def reboot(self, now_s: float) -> None:
        """A power cycle at ``now_s``: RAM state returns to its power-up values.

        Extended mode, the CAN-set zero, mode switches and PI multipliers are all lost (§2.3, §3,
        §4.1, §6); the motor is stopped and has no setpoint. The shaft keeps its physical angle and
        speed; the multi-turn count is lost, so the reported position restarts as the single-turn
        angle from the console zero, in [-180°, 180°) [I]. A reply already handed to the bus is in
        the transceiver and still goes out.
        """
        self.plant.advance(now_s)
        self._counters["reboots"] += 1
        self._power_up()

    def _power_cut(self, now_s: float) -> None:
        # No supply: no output power, the shaft is free (as after FD, §4.1).
        self.plant.advance(now_s)
        self.plant.set_control(Off())

    def _power_changed(self) -> None:
        self._changed()
        self.core_push()  # its C twin stands aside while the power is cut (HollowCore.core_push)

    def _power_up(self) -> None:
        self.enabled = False
        self.can_mode = CanMode.NORMAL
        self.ctrl_mode = self.power_up_mode
        self.setpoint = None
        self.pi_multipliers = dict.fromkeys(PiGain, 1.0)
        single_turn = (self.plant.position_deg - self.console_zero_deg + 180.0) % 360.0 - 180.0
        self.zero_offset_deg = self.plant.position_deg - single_turn
        self.plant.set_control(Off())

    # ---- what the motor reports ----

    @property
    def position_deg(self) -> float:
        """Multi-turn position from the mechanical zero (what the replies encode)."""
        return self.plant.position_deg - self.zero_offset_deg

    def status_reply(self) -> HollowReply:
        """The reply the motor would send now, in the format of its active interface and mode."""
        plant = self.plant
        if self.fd_enabled:
            return FdReply(
                position_deg=self.position_deg,
                velocity_rpm=plant.speed_dps / DPS_PER_RPM,
                current_raw=round(_clamp(plant.current_a / self.fd_current_a_per_count, *_INT16)),
                mode=self.ctrl_mode,
                running=self.enabled,
                temperature_c=round(_clamp(plant.temperature_c, *_TEMPERATURE_LIMITS_C)),
                slave_id=self.motor_id,
                model=self.model,
            )
        model = self.model
        speed = _clamp(
            plant.speed_dps / DPS_PER_RAD_S, -model.speed_full_scale_rad_s, model.speed_full_scale_rad_s
        )
        current = _clamp(plant.current_a, -model.current_full_scale_a, model.current_full_scale_a)
        if self.can_mode is CanMode.NORMAL:
            # A34: outside ±Pmax the code sticks at 0x0000 / 0xFFFF.
            full = model.position_full_scale_deg
            return NormalReply(
                motor_id=self.motor_id,
                position_deg=_clamp(self.position_deg, -full, full),
                speed_rad_s=speed,
                current_a=current,
                model=model,
            )
        return ExtendedReply(
            motor_id=self.motor_id,
            position_deg=_clamp(self.position_deg, *EXTENDED_POSITION_LIMITS_DEG),
            speed_rad_s=speed,
            current_a=current,
            model=model,
        )

    # ---- protocol model ----

    def _right_kind(self, frame: Frame) -> bool:
        if frame.is_extended_id:
            # §6 / A17: PI frames come classic or FD in CAN FD mode; classic CAN controllers
            # cannot receive FD frames at all.
            return self.fd_enabled or not frame.is_fd
        return frame.is_fd == self.fd_enabled

    def _control(self) -> Control:
        """The plant control for the present state (the mapping in the module docstring)."""
        held = self.setpoint
        if not self.enabled:
            return Off()
        if held is None:
            return CurrentControl(current_a=0.0)  # start without a setpoint: the safe choice
        if self.ctrl_mode is ControlMode.TORQUE:
            return CurrentControl(current_a=held.current_a)
        if self.ctrl_mode is ControlMode.VELOCITY:
            return SpeedControl(speed_dps=held.speed_dps, max_current_a=abs(held.current_a))
        return PositionControl(
            position_deg=held.target_deg + self.zero_offset_deg,
            max_speed_dps=abs(held.speed_dps),  # V = 0 holds still (§4.4)
            max_current_a=abs(held.current_a),
        )

    def _turnaround(self) -> float:
        if self.turnaround_jitter_s == 0.0:
            return self.turnaround_s
        return self.turnaround_s - self._rng.uniform(0.0, self.turnaround_jitter_s)

    def __repr__(self) -> str:
        kind = "fd" if self.fd_enabled else self.can_mode.name.lower()
        state = "enabled" if self.enabled else "stopped"
        return f"HollowMotor(id={self.motor_id}, {kind}, {self.ctrl_mode.name.lower()}, {state})"


def _clamp(value: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, value))
