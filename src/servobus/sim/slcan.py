"""The adapter side of the SLCAN (LAWICEL ASCII) protocol: a simulated USB-CAN(-FD) adapter.

Sans-IO. :meth:`SlcanAdapter.receive` takes the bytes a host wrote to the adapter's serial port
and returns the bytes to answer plus the frames to put on the bus; :meth:`SlcanAdapter.to_host`
turns a frame seen on the bus into the line the host reads. A pty attachment joins the two ends,
so python-can's own ``slcan`` interface (and any tool built on it) talks to simulated motors.

Command set (LAWICEL, plus the CAN FD extension of CANable-2.0-type firmware that the hollow
manual's USB adapter uses, spec hollow.md §8): ``S0``..``S8`` nominal bit rate, ``Y1``/``Y2``/``Y4``/``Y5``
data bit rate, ``sXXYY`` BTR registers (accepted; the nominal rate is then unknown), ``O`` open,
``L`` open listen-only, ``C`` close, ``t``/``T``/``r``/``R`` classic frames, ``d``/``D``/``b``/``B``
CAN FD frames, ``V`` version, ``N`` serial number, ``F`` status flags, ``Z`` timestamps. Success
is CR, failure BEL; a transmitted ``t``/``T`` is acknowledged ``z``/``Z`` + CR as LAWICEL does.
Configuration is refused while the channel is open, and frames while it is closed, as the
manual's set-up order (``S8``, ``Y5``, then ``O``) requires. A stray ``\\n`` (the manual's
``O\\r\\n``) is ignored.

The adapter's controller may have episodes (:class:`~servobus.sim.episodes.ControllerEpisodes`, on
the time given to :meth:`SlcanAdapter.receive` and :meth:`SlcanAdapter.to_host`), answered as a
LAWICEL adapter does: a frame it cannot transmit (transmit FIFO full, or bus-off) is answered BEL
instead of ``z``/``Z`` and never reaches the bus; ``F`` reports the transmit FIFO full (bit 1), and
bus-off as error warning, error passive and bus error (bits 2, 5, 7); while bus-off it receives
nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from servobus.frame import Frame
from servobus.sim.episodes import ControllerEpisodes

__all__ = ["DATA_BITRATES", "NOMINAL_BITRATES", "SlcanAdapter", "format_frame", "parse_frame"]

OK = b"\r"
ERROR = b"\a"
MAX_LINE = 1 + 8 + 1 + 128 + 1  # the longest frame line (extended FD, 64 bytes) and its CR

# LAWICEL's table; S7 is 800 kbit/s there (python-can sends S7 for 750 k, some firmware agrees).
NOMINAL_BITRATES = {
    0: 10_000,
    1: 20_000,
    2: 50_000,
    3: 100_000,
    4: 125_000,
    5: 250_000,
    6: 500_000,
    7: 800_000,
    8: 1_000_000,
    9: 83_300,
}
DATA_BITRATES = {1: 1_000_000, 2: 2_000_000, 4: 4_000_000, 5: 5_000_000}
_FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
# prefix -> (extended id, FD, bit-rate switch, remote)
_KINDS = {
    "t": (False, False, False, False),
    "T": (True, False, False, False),
    "r": (False, False, False, True),
    "R": (True, False, False, True),
    "d": (False, True, False, False),
    "D": (True, True, False, False),
    "b": (False, True, True, False),
    "B": (True, True, True, False),
}


def parse_frame(line: str) -> tuple[Frame | None, bool]:
    """A frame line without its CR -> (frame, is_remote). Remote frames carry no data (frame None).

    Raises:
        ValueError: the line is not a well-formed frame.
    """
    try:
        extended, fd, brs, remote = _KINDS[line[0]]
    except (IndexError, KeyError):
        raise ValueError(f"not a frame line: {line!r}") from None
    id_end = 9 if extended else 4
    try:
        ident = int(line[1:id_end], 16)
        dlc = int(line[id_end], 16)
    except (ValueError, IndexError):
        raise ValueError(f"bad identifier or DLC in {line!r}") from None
    if len(line[1:id_end]) != id_end - 1 or (not fd and dlc > 8):
        raise ValueError(f"bad identifier or DLC in {line!r}")
    length = _FD_LENGTHS[dlc] if fd else dlc
    payload = line[id_end + 1 :]
    if remote:
        if payload:
            raise ValueError(f"remote frame with data: {line!r}")
        return None, True
    if len(payload) != 2 * length:
        raise ValueError(f"DLC {dlc} needs {length} data bytes in {line!r}")
    try:
        data = bytes.fromhex(payload)
    except ValueError:
        raise ValueError(f"bad hex data in {line!r}") from None
    return Frame(
        arbitration_id=ident, data=data, is_extended_id=extended, is_fd=fd, bitrate_switch=brs
    ), False


def format_frame(frame: Frame) -> bytes:
    """The line (with CR) an adapter sends the host for ``frame``."""
    if frame.is_fd:
        prefix = (
            ("B" if frame.bitrate_switch else "D")
            if frame.is_extended_id
            else ("b" if frame.bitrate_switch else "d")
        )
        dlc = _FD_LENGTHS.index(len(frame.data))
    else:
        prefix = "T" if frame.is_extended_id else "t"
        dlc = len(frame.data)
    ident = f"{frame.arbitration_id:08X}" if frame.is_extended_id else f"{frame.arbitration_id:03X}"
    return f"{prefix}{ident}{dlc:X}{frame.data.hex().upper()}\r".encode()


@dataclass
class SlcanAdapter:
    """State of one simulated SLCAN adapter (one CAN channel).

    Attributes:
        is_open: the channel is on the bus (``O`` or ``L``).
        listen_only: opened with ``L``: frames are received, never sent.
        bitrate, data_bitrate: set by ``S``/``Y`` (None after ``s`` BTR registers).
        errors: commands answered with BEL; discarded: bytes of over-long lines dropped.
        episodes: the controller's full-queue and bus-off episodes (None: none).
        refused: frames answered BEL because of an episode (counted in ``errors`` too).
    """

    serial_number: str = "SB01"
    hardware_version: int = 10
    software_version: int = 13
    is_open: bool = False
    listen_only: bool = False
    bitrate: int | None = 1_000_000
    data_bitrate: int = 2_000_000
    timestamps: bool = False
    errors: int = 0
    discarded: int = 0
    episodes: ControllerEpisodes | None = None
    refused: int = 0
    _now_s: float = 0.0
    _line: bytearray = field(default_factory=bytearray, repr=False)

    def receive(self, data: bytes, now_s: float | None = None) -> tuple[bytes, list[Frame]]:
        """Bytes the host wrote at ``now_s`` (the episodes' clock) -> (bytes to answer, frames to
        transmit on the bus)."""
        if now_s is not None:
            self._now_s = now_s
        answer = bytearray()
        frames: list[Frame] = []
        for byte in data:
            if byte == 0x0D:
                reply, frame = self._command(self._line.decode("ascii", errors="replace"))
                self._line.clear()
                answer += reply
                if frame is not None:
                    frames.append(frame)
            elif byte == 0x0A:
                continue
            elif len(self._line) >= MAX_LINE:
                self.discarded += 1
            else:
                self._line.append(byte)
        return bytes(answer), frames

    def to_host(self, frame: Frame, now_s: float | None = None) -> bytes:
        """The line for a frame seen on the bus at ``now_s``, or nothing while the channel is closed
        (or the controller is bus-off)."""
        if self.episodes is not None and now_s is not None and not self.episodes.receiving(now_s):
            return b""
        return format_frame(frame) if self.is_open else b""

    def _fail(self) -> tuple[bytes, None]:
        self.errors += 1
        return ERROR, None

    def _command(self, line: str) -> tuple[bytes, Frame | None]:
        if not line:
            return OK, None  # a bare CR: LAWICEL hosts send it to flush the adapter's line
        head, arg = line[0], line[1:]
        if head in _KINDS:
            if not self.is_open or self.listen_only:
                return self._fail()
            try:
                frame, _remote = parse_frame(line)
            except ValueError:
                return self._fail()
            if self.episodes is not None and self.episodes.refusal(self._now_s) is not None:
                self.refused += 1
                return self._fail()  # not transmitted: LAWICEL's BEL instead of z/Z
            ack = b"Z\r" if head in "TR" else b"z\r" if head in "tr" else OK
            return ack, frame  # a remote frame is acknowledged; motors here answer no RTR
        if head in "SYs":
            if self.is_open:
                return self._fail()
            return self._configure(head, arg)
        if head in "OL" and not arg:
            if self.is_open:
                return self._fail()
            self.is_open, self.listen_only = True, head == "L"
            return OK, None
        if head == "C" and not arg:
            self.is_open = self.listen_only = False
            return OK, None
        if head == "V" and not arg:
            return f"V{self.hardware_version:02d}{self.software_version:02d}\r".encode(), None
        if head == "N" and not arg:
            return f"N{self.serial_number}\r".encode(), None
        if head == "F" and not arg:
            return b"F%02X\r" % self._status_flags(), None
        if head == "Z" and arg in ("0", "1"):
            self.timestamps = arg == "1"
            return OK, None
        return self._fail()

    def _status_flags(self) -> int:
        """LAWICEL's status byte: transmit FIFO full (0x02); bus-off as error warning, error
        passive and bus error (0x04 | 0x20 | 0x80)."""
        episodes = self.episodes
        if episodes is None:
            return 0
        episode = next((e for e in episodes.episodes if e.covers(self._now_s)), None)
        if episode is None:
            return 0
        return 0x02 if episode.kind == "queue_full" else 0xA4

    def _configure(self, head: str, arg: str) -> tuple[bytes, None]:
        if head == "S" and len(arg) == 1 and arg.isdigit() and int(arg) in NOMINAL_BITRATES:
            self.bitrate = NOMINAL_BITRATES[int(arg)]
        elif head == "Y" and len(arg) == 1 and arg.isdigit() and int(arg) in DATA_BITRATES:
            self.data_bitrate = DATA_BITRATES[int(arg)]
        elif head == "s" and len(arg) == 4 and all(c in "0123456789abcdefABCDEF" for c in arg):
            self.bitrate = None  # BTR0/BTR1 of an SJA1000 at 8 MHz: not modelled, rate unknown
        else:
            return self._fail()
        return OK, None
