"""Hypothesis settings shared by the oracle tests (tests/test_oracle_*.py).

SERVOBUS_ORACLE_EXAMPLES lowers the example count for slow builds (a sanitizer smoke run, say):
``SERVOBUS_ORACLE_EXAMPLES=300 pytest tests/test_oracle_*.py``.
"""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

__all__ = ["ORACLE_EXAMPLES", "oracle_settings"]

ORACLE_EXAMPLES = int(os.environ.get("SERVOBUS_ORACLE_EXAMPLES", "10000"))

# deadline=None: timing varies with the machine and with sanitizers; too_slow/data_too_large: the
# strategies build whole frame streams and batches on purpose.
oracle_settings = settings(
    max_examples=ORACLE_EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
