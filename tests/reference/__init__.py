"""Pure-Python reference of the servobus C core (csrc/), used only as a test oracle.

Written from the protocol specs (myactuator-v4.md §1.2 and §5; hollow.md §4, §5.3, §7, §9.4, §9.5) and
the contract in csrc/servobus_core.h, for clarity rather than speed: bitwise CRCs, one frame at a time,
de-framers as plain state machines over a growing buffer. The package never imports it.

* ``reference.crc``: CRC-16/MODBUS and CRC-32/ISO-HDLC (csrc/crc.c).
* ``reference.packing``: field scaling and the six frame layouts (csrc/bitpack.c).
* ``reference.deframe``: the three stream de-framers (csrc/deframe.c).
* ``reference.timing``: CAN / CAN FD bit counts, stuffing and CRC-15 built bit by bit (csrc/sim_timing.c).
* ``reference.settings``: the Hypothesis settings of tests/test_oracle_*.py.

tests/ is on sys.path (tests/conftest.py makes sure), so test modules import it as ``reference``.
"""
