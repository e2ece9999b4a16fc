"""Coded-patch front end (DexterCap Sec. 3.1-3.3): printable patches, and their template.

:mod:`~handcap.detect.alphabet` holds the glyphs and tags, :mod:`~handcap.detect.pattern`
the template (``pattern.toml``: every patch's tag grid and the corner ids it implies),
:mod:`~handcap.detect.session` the patches of a session (two hands, objects, the 2x2x2
cube) and :mod:`~handcap.detect.sheet` the printable SVG and PDF pages.
"""

from handcap.detect.alphabet import ALPHABET, DEXTERCAP_ALPHABET, check_alphabet, tag, tag_count, tag_index
from handcap.detect.pattern import PITCH, Patch, Pattern
from handcap.detect.session import HAND_PATCHES, OBJECT_PATCHES, session_pattern

__all__ = ["ALPHABET", "DEXTERCAP_ALPHABET", "HAND_PATCHES", "OBJECT_PATCHES", "PITCH", "Patch", "Pattern",
           "check_alphabet", "session_pattern", "tag", "tag_count", "tag_index"]
