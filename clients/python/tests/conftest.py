from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import pytest

sys.path.insert(0, str(Path(__file__).parent))

import nusense  # noqa: E402
from fake_daemon import FakeDaemon  # noqa: E402

FIXTURES = Path(__file__).parent / "fixtures"
REPO = Path(__file__).resolve().parents[3]

T = TypeVar("T")


def fixture_bytes(name: str) -> bytes:
    return (FIXTURES / name).read_bytes()


def eventually(check: Callable[[], T], timeout: float = 5.0) -> T:
    """``check()`` once it returns something true, polling for up to ``timeout`` s (Zenoh's declarations take a
    moment to reach the other peer)."""
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.02)


@pytest.fixture
def fake() -> Iterator[FakeDaemon]:
    daemon = FakeDaemon()
    yield daemon
    daemon.close()


@pytest.fixture
def client(fake: FakeDaemon) -> Iterator[nusense.Client]:
    conf = nusense.config([fake.endpoint], scouting=False)
    # Opening a peer waits half a second for scouting by default; here the one peer is known.
    conf.insert_json5("scouting/delay", "0")
    with nusense.connect(zenoh_config=conf) as c:
        yield c
