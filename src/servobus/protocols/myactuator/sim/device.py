"""The simulated MyActuator RMD-X motor (protocol V4.3 / V4.4) on a CAN bus: requests in, timed replies out.

Protocol model (spec ``myactuator-v4.md``; [000] = V4.4 manual, [002] = V4.3 manual) over the shared
codec used in reverse: requests are decoded with :func:`~servobus.protocols.myactuator.decode_request`
for the motor's revision, replies are built from the codec's reply classes with values from the
:class:`~servobus.sim.plant.Plant`, and sent ``turnaround_s`` after the request. The RS485 front is
:mod:`~servobus.protocols.myactuator.sim.rs485`; the memory (ROM/RAM, encoder, error latch) and the
reply builders are :mod:`~servobus.protocols.myactuator.sim.state`.

The model is told in parts by concern, all on the motor's one state
(:mod:`~servobus.protocols.myactuator.sim.base`): the frames it takes
(:mod:`~servobus.protocols.myactuator.sim.intake`), its output (``drive``), its faults and 0xB3
protection (``faults``), and the command handlers it dispatches to (``handlers``: ``reads``,
``loops``, ``settings``, ``streams``; typed against ``handlers.HandledMotor``, so none of them
imports this module). This module joins them: the device protocol, the C twin's entry points (the
motor moves its own plant and class onto the twin; ``core.MaCore`` only copies state) and power-up.

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
named). The next frame for the motor restores communication (``comm_restored``); control commands then
run again and release the brake (0xA1 after 0x77). 0 disables it. What V3 drivers are reported to do
besides (2b-t/myactuator_rmd_ros, pull request 4; ``trip_echo``, on by default): at the trip and about
every second while it lasts the motor sends ``F1 00 00 00 00 00 00 00`` on 0x240+ID
(``CommunicationTimeoutTripped``; "without data": the zeros are our choice; ``comm_trip_frames``), and
the frame that restores communication is echoed back byte for byte on its reply identifier and **not
executed** (``comm_echoed``); the next one is. Modelled on CAN (the RS485 front switches it off).
While tripped the motor is off the C path (``c_may_act``), so both paths agree.

0x20 index 3: while an error flag is set the motor sends 0x9A on 0x240+ID every 100 ms, the first
when the error appears (or reporting is switched on).
"""

from __future__ import annotations

import functools
from typing import Any, ClassVar

from servobus.core._lib import lib
from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import Revision
from servobus.protocols.myactuator.ids import check_motor_id, reply_id
from servobus.protocols.myactuator.sim import loops, reads, settings, streams
from servobus.protocols.myactuator.sim.base import RUN_MODE_POWER_UP
from servobus.protocols.myactuator.sim.core import MaCore, attached_class, register_model
from servobus.protocols.myactuator.sim.faults import ERROR_REPORT_PERIOD_S, Faults
from servobus.protocols.myactuator.sim.handlers import execute
from servobus.protocols.myactuator.sim.intake import CACHE_SIZE, Intake, reply_can_id
from servobus.protocols.myactuator.sim.reads import model_replies
from servobus.protocols.myactuator.sim.state import (
    DEFAULT_ENCODER_COUNTS_PER_TURN,
    DEFAULT_MODEL,
    DEFAULT_POLE_PAIRS,
    DEFAULT_VERSION_DATES,
    MYACTUATOR_PLANT_PARAMS,
    EncoderFrame,
    Settings,
    Stream,
)
from servobus.protocols.myactuator.sim.streams import stream_replies
from servobus.sim.coreplant import CorePlant
from servobus.sim.device import BusLink, Emission
from servobus.sim.plant import (
    Off,
    Plant,
    PlantParams,
)
from servobus.sim.power import PowerCuts

__all__ = ["DEFAULT_TURNAROUND_S", "ERROR_REPORT_PERIOD_S", "MyActuatorMotor", "Stream"]

# The manuals state no turnaround. 200 µs is what a V3 driver's 1 ms-or-faster command loop plus a CAN
# transmit-queue hop gives in practice [I]; the LK sibling states "within 0.25 ms" for its V2.36 drives.
DEFAULT_TURNAROUND_S = 200e-6
#: the handlers, by concern: importing them fills HANDLERS (handlers.py)
HANDLER_MODULES = (reads, loops, settings, streams)


class MyActuatorMotor(Intake, Faults, PowerCuts):
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
        trip_echo: after a 0xB3 trip, send 0xF1 frames and echo the first command unexecuted, as
            V3 drivers are reported to do (module docstring); False: the manuals' reading only.
        now_s: simulated time of power-up.

    Attributes:
        rom, ram: the stored and the running parameters (:class:`~.myactuator_state.Settings`).
        control: the commanded plant control (the plant gets ``Brake`` instead while the brake is locked).
        run_mode: the 0x70 value.
        brake_released: the 0x9A brake flag: the brake-release command is in effect.
        comm_tripped: 0xB3 protection has cut the output and no frame has arrived since.
        trip_echo: the constructor's argument (may be changed at any time).
        streams: active 0xB6 streams by command.
        feedforward_pct: the last 0x72/0x73 feed-forward (% of rated speed / current), or None.
        unresponsive: a simulator fault knob: the motor still acts on frames but never transmits.
        power_back_s: while a :meth:`~servobus.sim.power.PowerCuts.brownout` lasts, when the power
            comes back (None: powered).
        counters: frames and events by kind (see the module docstring).

    Raises:
        ValueError: bad id, revision, turnaround, model string, version date or ratings.
    """

    #: The family's C path (csrc/sim_myactuator.c), run by a network that has one (core.py).
    CORE_FAMILY: ClassVar[int] = lib.SB_FAMILY_MYACTUATOR
    _core: MaCore | None = None
    _core_base: ClassVar[type[MyActuatorMotor]]  # (the attached class's: the model's own class)

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
        trip_echo: bool = True,
        now_s: float = 0.0,
    ) -> None:
        check_motor_id(motor_id)
        if not isinstance(revision, Revision):
            raise ValueError(f"revision={revision!r} is not a Revision (V4_3, V4_4)")
        if not turnaround_s >= 0:
            raise ValueError(f"turnaround_s={turnaround_s!r} must be >= 0")
        if not (rated_current_a > 0 and rated_speed_dps > 0 and pole_pairs > 0):
            raise ValueError("rated_current_a, rated_speed_dps and pole_pairs must be > 0")
        version_date = DEFAULT_VERSION_DATES[revision] if version_date is None else version_date
        if ma.revision_from_version_date(version_date) is not revision:
            raise ValueError(f"version_date={version_date} reads as another revision than {revision.name}")
        model_replies(revision, model)  # refuse a model string the 0xB5 reply cannot carry, now
        plant = Plant(plant_params or MYACTUATOR_PLANT_PARAMS, now_s=now_s)
        super().__init__(
            name=name or f"myactuator{motor_id}",
            plant=plant,
            encoder=EncoderFrame(encoder_counts_per_turn, plant.params.gear_ratio),
            rom=Settings(motor_id=motor_id, can_id_filter=can_id_filter),
            revision=revision,
            version_date=version_date,
            model=model,
            turnaround_s=turnaround_s,
            motion_scales=motion_scales or ma.MOTION_SCALES[revision],
            has_brake=has_brake,
            rated_current_a=rated_current_a,
            rated_speed_dps=rated_speed_dps,
            pole_pairs=pole_pairs,
            trip_echo=trip_echo,
            now_s=now_s,
        )
        self.power_up(now_s)

    # ---- Device protocol ----

    @property
    def name(self) -> str:
        """The device name on its bus."""
        return self._name

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        """A frame seen on the bus at ``now_s``: act on it if it is for this motor, answer once.

        Returns:
            The reply (after ``turnaround_s``), or nothing (not for us, not decodable, no reply by the
            manual, streaming, or unresponsive).
        """
        if self.power_back_s is not None and not self.powered(now_s):
            self.advance(now_s)
            return []
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
        if self.comm_tripped and self.trip_echo:
            data = self._echo_unexecuted(frame.data, now_s)
        else:
            reply = self.handle(command, now_s)
            data = None if reply is None else _encode(reply)
        if data is None:
            return []
        can_id = reply_can_id(kind, motor_id)
        return [Emission(now_s + self.turnaround_s, Frame(arbitration_id=can_id, data=data))]

    def poll(self, now_s: float) -> list[Emission]:
        """Spontaneous frames due by ``now_s``: 0xB6 streams, 0x9A error reports and 0xF1 trip frames
        (0x240+ID); also trips the 0xB3 protection when its time has passed."""
        return [
            Emission(at, Frame(arbitration_id=reply_id(self.motor_id), data=reply.encode()))
            for at, reply in self.spontaneous(now_s)
        ]

    def next_deadline_s(self) -> float | None:
        """The earliest of: the 0xB3 trip (or, tripped, the next 0xF1 frame), the next stream frame,
        the next error report."""
        protection, report = self.protection_deadline_s(), self.next_report_s
        if protection is None:  # (tripped: the next 0xF1 frame instead)
            protection = self._next_trip_frame_s
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
        self.settle()
        # CorePlant is a Plant over C memory: the model uses it as its Plant, the twin shares it
        self._plant = CorePlant.adopt(self._plant, motor.plant, motor)
        self._core = MaCore(self, motor)
        self.__class__ = attached_class(type(self))  # (its C twin's pulled attributes)
        if link is not None:
            self._link = link
        self._core.push()

    def core_detach(self) -> None:
        """Leave the C twin and its network: its changes pulled, the plant back in Python."""
        if self._core is None:
            return
        self.settle()
        if isinstance(self._plant, CorePlant):
            self._plant = self._plant.to_python()
        self.__class__ = self._core_base
        self._core = None
        self._link = None

    def core_push(self) -> None:
        """Write what the C path reads into the twin (the network calls this after each call in)."""
        if self._core is not None:
            self._core.push()

    def _overhear(self, now_s: float) -> None:
        self.advance(now_s)

    # ---- shared with the RS485 front ----

    def spontaneous(self, now_s: float) -> list[tuple[float, Reply]]:
        """Advance to ``now_s`` and return the stream frames and error reports due, with their times."""
        if self.power_back_s is not None and not self.powered(now_s):
            self.advance(now_s)
            return []
        self.advance(now_s)
        out: list[tuple[float, Reply]] = []
        streams = self.streams
        if streams and self._core is not None and self._core.runs_streams():
            streams = {}  # its C twin runs them (sb_ma_poll)
        if streams:
            stream_replies(self, streams, now_s, out)
        self._fault_frames(now_s, out)
        if out and self.unresponsive:
            self._counters["unanswered"] += len(out)
            return []
        return out

    def handle(self, command: Command, now_s: float, *, rs485: bool = False) -> Reply | None:
        """Act on a decoded request addressed to this motor; return the reply to send, if any."""
        if self.power_back_s is not None and not self.powered(now_s):
            return None  # (the RS485 front's way in: its line is dead too)
        self._counters["accepted"] += 1
        self._heard(now_s)
        reply = execute(self, command, now_s, rs485=rs485)
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

    # ---- power and dispatch ----

    def reboot(self, now_s: float) -> None:
        """A power cycle at ``now_s``: RAM is loaded from ROM, streams stop, the output is off and the
        brake locked (§4.30), the run time restarts. Physical shaft angle and speed are kept."""
        self.advance(now_s)
        self._counters["reboots"] += 1
        self.power_up(now_s)

    def _power_cut(self, now_s: float) -> None:
        # No supply: the output is off and the power-off brake holds (a brake is locked unpowered,
        # §4.30); nothing runs, nothing streams or reports until the power-up.
        self.advance(now_s)
        self.brake_released = False
        self.streams = {}
        self.next_report_s = None
        self.set_control(Off(), self.run_mode)

    def _power_changed(self) -> None:
        self._changed()
        if self._core is not None:
            self._core.push()  # its C twin stands aside while the power is cut, and acts again after

    def power_up(self, now_s: float) -> None:
        keep_turns = self.rom.save_multi_turn and not self.rom.clear_multi_turn
        self.rom.clear_multi_turn = False
        self.ram = self.rom.copy()
        self.encoder.offset_counts = self.ram.encoder_offset_counts
        self.encoder.power_up(self.plant.motor_position_deg, keep_turns=keep_turns)
        self.errors.power_up()
        self.brake_released = False
        self.comm_tripped = False
        self._next_trip_frame_s = None
        self.streams = {}
        self.feedforward_pct = None
        self.boot_s = self._last_heard_s = now_s
        self.next_report_s = None
        self.set_control(Off(), RUN_MODE_POWER_UP)
        self.update_reports(now_s)

    def __repr__(self) -> str:
        state = "on" if self.enabled else "off"
        errors = self.errors.flags
        return f"MyActuatorMotor(id={self.motor_id}, {self.revision.name}, {state}, errors={errors!r})"


register_model(MyActuatorMotor)  # what the C path reproduces (core.py), before anything can patch it


# A motor encodes the same few replies over and over (and decodes the same few requests, intake.py):
# both are pure, so each is done once per distinct value.
@functools.lru_cache(maxsize=CACHE_SIZE)
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
    if len(_ENCODED) >= CACHE_SIZE:
        _ENCODED.clear()
    data = _encode_cached(reply)
    _ENCODED[id(reply)] = (reply, data)
    return data
