"""Shared fixtures. Real data is read from ``../shared/data`` beside the checkout."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: ``../shared/data`` beside the checkout, or the folder in ``HANDCAP_SHARED_DATA``.
SHARED_DATA = Path(os.environ.get("HANDCAP_SHARED_DATA") or REPO.parent / "shared" / "data")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real recordings (``../shared/data``); CI has it beside the checkout.

    Tests that need it are skipped, saying why, where it is absent (README, "Test data").
    """
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder {SHARED_DATA} is absent: put the shared data beside the checkout "
                    "(../shared/data) or set HANDCAP_SHARED_DATA; see README, 'Test data'")
    return SHARED_DATA
