"""Rendered scenes shared by the detector's tests (rendering is the slow part)."""

from __future__ import annotations

import pytest

from handcap import HandcapError


@pytest.fixture(scope="session")
def scenes():
    """Three rendered scenes of the patched hand, tags in DexterCap's alphabet (skipped without OpenGL)."""
    pytest.importorskip("moderngl", reason="rendered scenes need moderngl (extra 'images')")
    from handcap.detect.scenes import SceneMaker
    try:
        maker = SceneMaker(11, scale=(0.6, 1.0), alphabet="0123456789ACEFHPUY")
    except HandcapError as err:
        pytest.skip(f"no headless OpenGL here: {err}")
    try:
        return [maker.scene() for _ in range(3)]
    finally:
        maker.close()
