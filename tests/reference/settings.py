"""Hypothesis settings shared by the oracle tests (tests/test_oracle_*.py).

The example count follows the Hypothesis profile (tests/conftest.py: ``default`` 200, ``ci`` 3,000,
``quick`` 50; HYPOTHESIS_PROFILE chooses). SERVOBUS_ORACLE_EXAMPLES overrides it for these tests alone
(the sanitizer smoke run, say): ``SERVOBUS_ORACLE_EXAMPLES=500 pytest tests/test_oracle_*.py``.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

__all__ = ["ORACLE_EXAMPLES", "oracle_settings"]

_override = os.environ.get("SERVOBUS_ORACLE_EXAMPLES")

# Settings left unnamed here come from the profile loaded when this module is imported (conftest loads
# it before any test module). deadline=None: timing varies with the machine and with sanitizers;
# too_slow/data_too_large: the strategies build whole frame streams and batches on purpose.
oracle_settings = settings(
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    **({"max_examples": int(_override)} if _override else {}),
)

ORACLE_EXAMPLES: int = oracle_settings.max_examples
