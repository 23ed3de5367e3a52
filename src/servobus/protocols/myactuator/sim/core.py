"""The simulated MyActuator motor's C twin: the glue between the model and csrc/sim_myactuator.c.

A network that runs its motors in C (``servobus.sim.corenet``) gives each model an ``sb_simmotor``
(:meth:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor.core_attach`). The C path then
answers the control-loop traffic itself (set-points, status reads, motion mode, 0xB6 streams) while
the model's guards allow it (:func:`c_may_act`), and hands everything else to the model
(``SB_HOT_COLD``). Both sides keep one state:

* **push** (:meth:`MaCore.push`, after every call into the model): everything the C path reads, the
  guard (``motor.hot``) and the model's own next deadline (``motor.py_deadline_s``);
* **pull** (:meth:`MaCore.pull`, before the model reads anything): what the C path changed, flagged
  in ``sb_ma_state.dirty``: counters, control and run mode, brake, feed-forward, the time last heard
  (0xB3) and the streams.

While attached, the model's class is its "attached" subclass (:func:`attached_class`): the same
class but for pulled attributes (``control``, ``run_mode``, ``brake_released``,
``feedforward_pct``, ``streams``, ``_last_heard_s``: a read or a write pulls first), a ``settle``
that pulls, and an ``unresponsive`` whose change reaches C at once. Detached, it is its own class
again, with plain attributes: a model without a C twin runs exactly the reference code. The plant
lives in ``motor.plant`` (a :class:`~servobus.sim.coreplant.CorePlant` over it), so both sides
integrate the same state.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol, TypeVar, cast

from servobus.core._lib import ffi, lib
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.enums import AccelIndex, RunMode, StreamableCommand
from servobus.protocols.myactuator.revision import Revision
from servobus.protocols.myactuator.sim.state import EncoderFrame, ErrorLatch, Settings, Stream
from servobus.sim.coreplant import control_fields, control_from_fields

__all__ = ["COUNTER_NAMES", "MaCore", "Twinned", "attached_class", "c_may_act", "register_model"]


class Twinned(Protocol):
    """What the C twin reads of the model (MyActuatorMotor is one): its configuration and guards."""

    revision: Revision
    has_brake: bool
    pole_pairs: int
    turnaround_s: float
    rated_current_a: float
    motion_scales: ma.MotionScales
    ram: Settings
    encoder: EncoderFrame
    errors: ErrorLatch
    comm_tripped: bool
    next_report_s: float | None
    power_back_s: float | None
    __dict__: dict[str, Any]

    def settle(self) -> None: ...
    def tally(self, kind: str, n: int = 1) -> None: ...
    def listen_ids(self) -> frozenset[int]: ...
    def next_deadline_s(self) -> float | None: ...


#: The model's Counter keys the C path counts, by their index in ``motor.counters`` (SB_MA_CTR_*).
COUNTER_NAMES = (
    "received",
    "ignored_kind",
    "ignored_id",
    "filtered",
    "accepted",
    "replied",
    "silenced_by_active_reply",
    "brake_locked",
    "stream_frames",
    "stream_skipped",
)
assert len(COUNTER_NAMES) == lib.SB_MA_N_COUNTERS

_INT64 = 1 << 62  # encoder counts the C path takes (sim_myactuator.c COUNT_LIMIT is 4e18 < 2**62)
_COUNT_LIMIT = 4 * 10**18
_INT32 = 1 << 31

M = TypeVar("M", bound=Twinned)


def _pulled(name: str) -> property:
    """An attribute of an attached model that its C twin may change: a read or a write pulls first.

    The value stays in the instance's ``__dict__`` under its own name (where the plain attribute of
    a detached model keeps it); :meth:`MaCore.pull` writes there directly.
    """

    def get(self: Any) -> Any:
        self._core.pull()
        return self.__dict__[name]

    def set_(self: Any, value: Any) -> None:
        self._core.pull()  # C's changes first, or a later pull would undo this
        self.__dict__[name] = value

    return property(get, set_)


_PULLED = ("control", "run_mode", "brake_released", "feedforward_pct", "streams", "_last_heard_s")
_ATTACHED: dict[type, type] = {}


def attached_class(cls: type[M]) -> type[M]:
    """``cls`` as a model attached to a C twin sees it (built once per class; see the module)."""
    found = _ATTACHED.get(cls)
    if found is not None:
        return found
    base_settle = cls.settle

    def settle(self: Any) -> None:
        self._core.pull()
        base_settle(self)

    def get_unresponsive(self: Any) -> bool:
        value: bool = self.__dict__["unresponsive"]
        return value

    def set_unresponsive(self: Any, value: bool) -> None:
        self.__dict__["unresponsive"] = value
        self._core.push()  # set from outside the network's calls: C stops (or starts) answering now
        self._changed()

    namespace: dict[str, Any] = {name: _pulled(name) for name in _PULLED}
    namespace.update(
        __module__=cls.__module__,
        __qualname__=cls.__qualname__,
        __doc__=cls.__doc__,
        _core_base=cls,
        settle=settle,
        unresponsive=property(get_unresponsive, set_unresponsive),
    )
    found = _ATTACHED[cls] = cast("type[M]", type(cls.__name__, (cls,), namespace))
    return found


# Methods whose behaviour the C path reproduces. While any of them is not the model's own as written
# (a subclass overrides it, a test patches the class to watch it), the Python path does everything.
_MODELLED = (
    "receive",
    "poll",
    "handle",
    "spontaneous",
    "advance",
    "readings",
    "next_deadline_s",
    "listen_ids",
    "settle",
    "_route",
    "_decode",
    "control_command",
    "set_control",
    "apply_plant",
    "_heard",
    "current_limit_a",
    "target_deg",
    "status1_reply",
)
_ORIGINALS: list[tuple[str, object]] = []


def register_model(cls: type) -> None:
    """Record the model's methods as written (device.py calls this as it defines the class)."""
    _ORIGINALS[:] = [(name, getattr(cls, name)) for name in _MODELLED]


def _class_ok(cls: type) -> bool:
    cls = getattr(cls, "_core_base", cls)  # an attached class: the model's own
    return bool(_ORIGINALS) and all(getattr(cls, name) is method for name, method in _ORIGINALS)


def c_may_act(device: Twinned) -> bool:
    """The model's guards: the C path reproduces the model in this state (no error flag latched or
    reported, not unresponsive, powered, not cut off by 0xB3, an encoder and ids the C state holds)."""
    encoder = device.encoder
    return (
        not device.__dict__["unresponsive"]
        and device.power_back_s is None
        and not device.errors.flags
        and not device.comm_tripped
        and device.next_report_s is None
        and 1 <= encoder.counts_per_turn <= 65536
        and -_COUNT_LIMIT < encoder.base_counts < _COUNT_LIMIT
        and -_COUNT_LIMIT < encoder.offset_counts < _COUNT_LIMIT
        and 0 <= device.ram.comm_timeout_ms < _INT64
        and -_INT32 <= device.pole_pairs < _INT32
        and _class_ok(type(device))
    )


def _fields(scales: Any) -> list[tuple[float, float, float, float, float]]:
    return [(s.lo, s.hi, s.origin, s.codes, s.span) for s in scales]


class MaCore:
    """One model's C twin (``sb_simmotor`` of family MYACTUATOR): push, pull, and whether C runs now.

    Args:
        device: the model.
        motor: its ``sb_simmotor *`` (owned by the network; zeroed).
    """

    __slots__ = ("_config", "_control", "_stream", "device", "motor", "state")

    def __init__(self, device: Twinned, motor: Any) -> None:
        self.device = device
        self.motor = motor
        self.state = ffi.cast("sb_ma_state *", motor.state)
        self._config: tuple[Any, ...] | None = None  # the configuration last written
        self._control: object = None  # the control object last written or pulled
        self._stream: Callable[..., Any] = Stream

    def runs_streams(self) -> bool:
        """The C path runs the 0xB6 streams (sb_ma_next_deadline / sb_ma_poll), not the model."""
        return c_may_act(self.device)

    def pull(self) -> None:
        """Take what the C path changed into the model (cheap when it changed nothing)."""
        st = self.state
        dirty = st.dirty
        if not dirty:
            return
        st.dirty = 0
        values = self.device.__dict__
        if dirty & lib.SB_MA_DIRTY_COUNTERS:
            counts, tally = self.motor.counters, self.device.tally
            streamed = False
            for i, name in enumerate(COUNTER_NAMES):
                n = counts[i]
                if n:
                    tally(name, n)
                    counts[i] = 0
                    streamed = streamed or name == "stream_frames"
            if streamed:
                tally("stream_skipped", 0)  # the model adds its (often 0) skips with every frame
        if dirty & lib.SB_MA_DIRTY_CONTROL:
            values["control"] = self._control = control_from_fields(st.control)
            values["run_mode"] = RunMode(st.run_mode)
            values["brake_released"] = bool(st.brake_released)
            values["feedforward_pct"] = int(st.feedforward_pct) if st.has_feedforward else None
        if dirty & lib.SB_MA_DIRTY_HEARD:
            values["_last_heard_s"] = float(st.last_heard_s)
        if dirty & lib.SB_MA_DIRTY_STREAMS:
            make = self._stream
            values["streams"] = {
                StreamableCommand(s.command): make(
                    interval_s=s.interval_s, origin_s=s.origin_s, count=int(s.count)
                )
                for s in st.streams[0 : st.n_streams]
            }

    def push(self) -> None:
        """Write everything the C path reads, the guard and the model's own next deadline."""
        self.pull()
        device, motor, st = self.device, self.motor, self.state
        values = device.__dict__
        hot = c_may_act(device)
        ram, encoder = device.ram, device.encoder
        accel = ram.acceleration_dps_s
        # The configuration changes rarely (0x20, 0x43, 0xB3, a zero, a restart): written when it did.
        config = (
            hot,
            ram.motor_id,
            device.revision,
            ram.can_id_filter,
            device.has_brake,
            device.pole_pairs,
            encoder.counts_per_turn,
            encoder.base_counts,
            encoder.offset_counts,
            encoder.gear_ratio,
            ram.comm_timeout_ms,
            device.rated_current_a,
            accel[AccelIndex.POSITION_ACCELERATION],
            accel[AccelIndex.SPEED_ACCELERATION],
            device.turnaround_s,
            device.motion_scales,
        )
        if config != self._config:
            self._write_config(config)
        control = values["control"]
        if control is not self._control:  # the model set a control of its own (or pulled C's)
            st.control = control_fields(control)
            self._control = control
        st.brake_released = int(bool(values["brake_released"]))
        st.run_mode = int(values["run_mode"])
        feedforward = values["feedforward_pct"]
        st.has_feedforward = int(feedforward is not None)
        st.feedforward_pct = 0 if feedforward is None else feedforward
        st.last_heard_s = values["_last_heard_s"]
        streams = values["streams"]
        st.n_streams = len(streams)
        for i, (command, stream) in enumerate(streams.items()):
            st.streams[i] = (int(command), stream.count, stream.interval_s, stream.origin_s)
        motor.hot = int(hot)
        deadline = device.next_deadline_s()
        motor.py_deadline_s = math.inf if deadline is None else deadline

    def _write_config(self, config: tuple[Any, ...]) -> None:
        (hot, motor_id, revision, can_id_filter, has_brake, pole_pairs, cpt, base, offset, gear,
         timeout_ms, rated_a, accel_position, accel_speed, turnaround_s, scales) = config  # fmt: skip
        motor, st = self.motor, self.state
        motor.family = lib.SB_FAMILY_MYACTUATOR
        motor.turnaround_s = turnaround_s
        ids = sorted(self.device.listen_ids())
        motor.listen_all = 0
        motor.n_listen = len(ids)
        motor.listen[0 : len(ids)] = ids
        st.motor_id = motor_id
        st.revision = lib.SB_MA_V4_4 if revision is Revision.V4_4 else lib.SB_MA_V4_3
        st.can_id_filter = int(bool(can_id_filter))
        st.has_brake = int(bool(has_brake))
        # c_may_act() checked that these fit; a state C cannot take is never read (not hot)
        st.pole_pairs = pole_pairs if hot else 1
        st.counts_per_turn = cpt if hot else 1
        st.base_counts = base if hot else 0
        st.offset_counts = offset if hot else 0
        st.comm_timeout_ms = timeout_ms if hot else 0
        st.encoder_gear_ratio = gear
        st.rated_current_a = rated_a
        st.position_acceleration_dps_s = accel_position
        st.speed_acceleration_dps_s = accel_speed
        st.motion_command = _fields(scales.command_scales())
        st.motion_reply = _fields(scales.reply_scales())
        self._config = config
