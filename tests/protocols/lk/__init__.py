"""Tests of the LK family (servobus.protocols.lk)."""
