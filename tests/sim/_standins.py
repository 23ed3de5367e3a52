"""Minimal stand-in devices: the network's and attachments' rules, tested apart from any protocol."""

from __future__ import annotations

from dataclasses import dataclass, field

from servobus.core import MyActuatorRs485Deframer
from servobus.frame import Frame
from servobus.sim.device import Emission, SerialEmission

TURNAROUND_S = 100e-6


@dataclass
class Responder:
    """Answers a frame on 0x140+id with the same data on 0x240+id after TURNAROUND_S."""

    motor_id: int
    seen: list[tuple[float, Frame]] = field(default_factory=list)

    @property
    def name(self) -> str:
        return f"motor{self.motor_id}"

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        self.seen.append((now_s, frame))
        if frame.arbitration_id != 0x140 + self.motor_id:
            return []
        reply = Frame(arbitration_id=0x240 + self.motor_id, data=frame.data, is_fd=frame.is_fd)
        return [Emission(now_s + TURNAROUND_S, reply)]

    def poll(self, now_s: float) -> list[Emission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


@dataclass
class Streamer:
    """Sends a frame every ``period_s`` on its own."""

    period_s: float
    next_s: float = 0.0
    name: str = "streamer"

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        return []

    def poll(self, now_s: float) -> list[Emission]:
        out = []
        while self.next_s <= now_s:
            out.append(Emission(self.next_s, Frame(arbitration_id=0x7FF, data=b"\x01")))
            self.next_s += self.period_s
        return out

    def next_deadline_s(self) -> float | None:
        return self.next_s


@dataclass
class SerialResponder:
    """Answers a 0x3E frame addressed to it with the same frame (an RS485 echo), after TURNAROUND_S."""

    motor_id: int
    deframer: MyActuatorRs485Deframer = field(default_factory=MyActuatorRs485Deframer)

    @property
    def name(self) -> str:
        return f"motor{self.motor_id}"

    def receive_bytes(self, data: bytes, now_s: float) -> list[SerialEmission]:
        return [
            SerialEmission(now_s + TURNAROUND_S, bytes(frame))
            for frame in self.deframer.feed(data)
            if frame[1] == self.motor_id
        ]

    def poll(self, now_s: float) -> list[SerialEmission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None


@dataclass
class Sniffer:
    """A passive node: records every frame on the wire with the time its transmission ended."""

    name: str = "sniffer"
    seen: list[tuple[float, Frame]] = field(default_factory=list)

    def receive(self, frame: Frame, now_s: float) -> list[Emission]:
        self.seen.append((now_s, frame))
        return []

    def poll(self, now_s: float) -> list[Emission]:
        return []

    def next_deadline_s(self) -> float | None:
        return None
