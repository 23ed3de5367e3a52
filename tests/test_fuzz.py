"""The fuzz targets of tests/_fuzz.py under Hypothesis, in every test run (the long run, millions of
inputs per target under ASan + UBSan with atheris, is ``python bench/reliability.py fuzz``).

Each target raises on a broken promise (only ProtocolError out of a decoder, a transport that stays
OPEN, a scheduler that resolves only the right request, ...; see tests/_fuzz.py). Inputs that once
broke one are kept below as regression tests.
"""

from __future__ import annotations

import base64
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import _fuzz
from _fuzz import TARGETS

# Inputs a fuzzer found, by target: each broke the target once (see the comment by it).
REGRESSIONS: dict[str, list[bytes]] = {
    # atheris, 2026-11-23: a reply stamped 0.0 (a virtual clock's first instant) was taken for an
    # unstamped one and resolved a request sent at 0.0 sooner than min_reply_s allows.
    "scheduler_intake": [
        base64.b64decode(
            "////l5MZk5MZAhkZJZeTGZMIGS6X+BX//+YZkQgZLpf4Ff//5uZd/ebm2peTGZMIAuoZGQIZGSX/////l5MZk+b95uZBQUFB"
            "QUFB2peTGZMIAupBGRkCGRkl/////5eTGZOTGQIZGSWXkxmTCBkul/gV5ub95ubal5PebAgC6hkZAhkZJRkZApfm"
        ),
        # the sanitized run, 2026-11-28: a reply that does not decode fails its request (issue
        # [control]); the harness still asked every request a frame resolved to be REPLIED.
        base64.b64decode(
            "vWBncKqs0X5qFgHD8lKNh1yFZDVXETsMXxbFAPgnazvLEGpH/G6WNf2CD3pMyHcE9iHXzV3QZV8jHgmuBnNLS4Y4SWiqBcZI"
            "qSoL7ixNCE6CrCQiMDiWUsLTjqpdVsOiYokLswFNw+xNl4PUjNOF9b469p2hlUH9Q6jvQDPonN7ALI58+6JfaYFVobl5d3xB"
            "zoL2GP4gcCrNBVD1CjpaWKNNYq9AKrZ7IQWM15XunJTqXsaJs2F4j5LHM/7L6NwJ828Cz8GYgJVf6SrsTLdMtPnh7xMW+ifJ"
            "CA/Un1EwFJqmfwzcvtmZm2KxZO2+lHdxPvLqWdDZoF0hsZxphm8BoyHVHXJovbW0yA=="
        ),
        # and one that came before its send report, judged (failed) when the report came
        base64.b64decode(
            "qWgG4DrIJCxXD7PRjCj5W8xN8c6ySgaE7Cg/unNH2q1B+IFDAXEwoJnOK1pi1YXPThu3LZ9K1LtGr/ATAsaN9E3q2u6vhsk7"
            "KYrZ5bimPBH2TymFj++42HnqoogY1T7TpuEokplUlNo5Im1ChhSRHHTkg/4vcvsygpVqn4iST6sMWLzUG/Xra7VcUKf6+h/o"
            "Dw/DlvZyJd3Ku64/FUoJ8sAE27xv53CQMf+Bqdfm64pcSEvwy7tMxaGSTF7bhj3BuBY3OPIdDZbvxpFZHhSiflF1KotBb/6H"
            "qgvwzSclK5hzNpfn+3s4dVNtMEv9+mt1NDL4IqwzkY2QVech2ohrM2p4BiJzostpom1BuwZfgQIYF5/p0LYlEhhrDslPKP1w"
            "QUQrAydk99hPOGWUbBGHNJXtw1AgQfNQcGmkgXXMG3h2MW1S3KdoYMyBg0NSe+gLEc8n8vYdEcEyBFIUTvkYb3Xb/0c7Rh36"
            "CbMM+17CopHlZJ4b/7GDkrNLH8EBmv7whSTrMEkkEYEJQZ991svsSQMBwPgFsIs7iW3y8iT03vOyRi1bpgay9A5j6Cx7/t4R"
            "cS2Rh9w9GqSKqanrrR+imbUCYAuvmQ/ELB7cvvaaGG02KTp5z7NNqnwa2Cv0B2XmslY="
        ),
    ],
}


@pytest.fixture(scope="module", autouse=True)
def _rigs() -> Iterator[None]:
    yield
    _fuzz.close_rigs()


def test_every_promised_target_is_there() -> None:
    assert set(TARGETS) == {
        "myactuator_can",
        "myactuator_rs485",
        "lk_can",
        "hollow_can",
        "hollow_rs485",
        "deframe_myactuator_rs485",
        "deframe_hollow_transparent",
        "deframe_modbus_rtu",
        "deframe_slcan",
        "transport_slcan",
        "transport_rs485",
        "scheduler_intake",
    }


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_fuzz(name: str) -> None:
    run = TARGETS[name]

    @settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(st.binary(max_size=300))
    def fuzz(data: bytes) -> None:
        run(data)

    fuzz()


def test_regressions() -> None:
    for name, inputs in sorted(REGRESSIONS.items()):
        for data in inputs:
            TARGETS[name](data)
