"""Coded patches (DexterCap Sec. 3.1.2): the glyphs and tags, the session template and the printable pages.

:mod:`~handcap.patterns.alphabet` holds the glyphs and tags, :mod:`~handcap.patterns.pattern`
the template (``pattern.toml``: every patch's tag grid and the corner ids it implies),
:mod:`~handcap.patterns.session` the patches of a session (two hands, objects, the 2x2x2 cube),
:mod:`~handcap.patterns.glyphs` the drawing of a patch (glyph outlines from a font) and
:mod:`~handcap.patterns.sheet` the printable SVG and PDF pages,
:mod:`~handcap.patterns.foreign` the templates of patches another generator printed (DexterCap's JSON) and
:mod:`~handcap.patterns.layout` the marker layout of a template's hand patches. The renderer
(:mod:`handcap.synth.images`) and the detector (:mod:`handcap.detect`) both use them.
"""

from handcap.patterns.alphabet import ALPHABET, DEXTERCAP_ALPHABET, check_alphabet, tag, tag_count, tag_index
from handcap.patterns.pattern import PITCH, Patch, Pattern
from handcap.patterns.session import HAND_PATCHES, OBJECT_PATCHES, session_pattern

__all__ = ["ALPHABET", "DEXTERCAP_ALPHABET", "HAND_PATCHES", "OBJECT_PATCHES", "PITCH", "Patch", "Pattern",
           "check_alphabet", "session_pattern", "tag", "tag_count", "tag_index"]
