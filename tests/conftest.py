"""Shared fixtures. Real data is read from ``../shared/data`` beside the checkout."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real recordings (``../shared/data``); CI has it beside the checkout."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real data folder {SHARED_DATA} is missing; handcap's tests read it from ../shared/data")
    return SHARED_DATA
