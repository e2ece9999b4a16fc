"""The glyphs of coded patches and the two-character tags made from them.

Every white square of a coded patch carries a tag: two glyphs, the first one
underlined so that a reader knows which way is up (DexterCap, Sec. 3.1.2). A
session needs one distinct tag per white square of every patch it uses: two
hands, a few objects and a 2x2x2 cube take 700-800 of them.

:data:`ALPHABET` (27 glyphs, 729 tags) keeps the characters whose shapes stay
apart in bold monospace fonts once the underline has fixed the reading
direction: no ``O``/``D``/``Q`` beside ``0``, no ``I`` beside ``1``, no ``S``,
``Z``, ``B``, ``G`` beside ``5``, ``2``, ``8``, ``6``, no ``V`` beside ``U``
and ``Y``. :data:`DEXTERCAP_ALPHABET` is the 18-glyph set of DexterCap's
printed patches (324 tags); the detector reads either, or any other given
with ``--alphabet``.
"""

from __future__ import annotations

from handcap.core.errors import HandcapError

#: handcap's glyphs: 10 digits and 17 letters, 27**2 = 729 tags.
ALPHABET = "0123456789ACEFHJKLMNPRTUWXY"
#: The 18 glyphs of DexterCap's patches (324 tags).
DEXTERCAP_ALPHABET = "0123456789ACEFHPUY"
#: Every glyph the detector's block reader knows (:data:`handcap.detect.reader.GLYPHS`): digits, capitals and a
#: few symbols of bold monospace fonts.
READABLE = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ#%&+=@"
#: Characters that cannot be glyphs: a black square is written ``""`` in a template, and these have other uses
#: or no visible shape.
_RESERVED = set("*-\"'\\ \t\n")


#: Pairs of glyphs that bold monospace fonts draw alike, so that a reader trained on some fonts mistakes one for the
#: other in a font it never saw (on 200 rendered scenes in Noto Sans Mono Bold, 20 of the shipped reader's 26 trusted
#: misreadings in random 27-glyph alphabets swapped such a pair; handcap's and DexterCap's alphabets hold none).
LOOKALIKES = ("0O", "0D", "0Q", "0@", "OD", "OQ", "DQ", "1I", "2Z", "7Z", "5S", "6G", "8B", "UV", "VY", "+=", "A&")


def lookalikes(alphabet: str) -> list[str]:
    """The pairs of :data:`LOOKALIKES` that ``alphabet`` holds both glyphs of.

    Parameters
    ----------
    alphabet : str

    Returns
    -------
    list of str
        Two-glyph strings, in the order of :data:`LOOKALIKES`.
    """
    return [pair for pair in LOOKALIKES if pair[0] in alphabet and pair[1] in alphabet]


def lookalike_warning(alphabet: str) -> list[str]:
    """A warning for an alphabet that holds glyphs fonts draw alike (none for one that does not).

    Parameters
    ----------
    alphabet : str

    Returns
    -------
    list of str
        No line, or one.
    """
    pairs = lookalikes(alphabet)
    if not pairs:
        return []
    said = ", ".join(f"{p[0]} and {p[1]}" for p in pairs[:6])
    said += f" and {len(pairs) - 6} more" if len(pairs) > 6 else ""
    return [f"alphabet {alphabet}: holds glyphs that fonts draw alike ({said}); printed in a font the reader never "
            "saw, their tags are misread more often (with the vote over a template most are corrected); handcap's "
            f"alphabet {ALPHABET} leaves them out"]


def check_alphabet(alphabet: str) -> str:
    """``alphabet`` if it can make tags: 2 or more distinct printable glyphs, none reserved.

    Parameters
    ----------
    alphabet : str
        The glyphs, in the order that numbers the tags.

    Returns
    -------
    str
        The same string.

    Raises
    ------
    HandcapError
        When a glyph repeats, is a space or a reserved character, or there are fewer than 2.
    """
    if not isinstance(alphabet, str) or len(alphabet) < 2:
        raise HandcapError(f"alphabet {alphabet!r}: give 2 or more glyphs, e.g. {ALPHABET}")
    seen = set()
    for ch in alphabet:
        if ch in seen:
            raise HandcapError(f"alphabet {alphabet!r}: glyph {ch!r} appears twice; each glyph once")
        if ch in _RESERVED or not ch.isprintable():
            raise HandcapError(f"alphabet {alphabet!r}: {ch!r} cannot be a glyph (no spaces, quotes, '*' or '-')")
        seen.add(ch)
    return alphabet


def tag_count(alphabet: str = ALPHABET) -> int:
    """How many distinct tags ``alphabet`` makes (its length squared).

    Parameters
    ----------
    alphabet : str

    Returns
    -------
    int
    """
    return len(check_alphabet(alphabet)) ** 2


def tag(index: int, alphabet: str = ALPHABET) -> str:
    """The ``index``-th tag of ``alphabet``.

    Tag ``k = a + n b`` (``n`` glyphs) is ``alphabet[a] + alphabet[(a + b) % n]``: a
    bijection of ``0 .. n**2 - 1`` onto the pairs in which consecutive tags differ in
    both glyphs, so one misread glyph does not turn a tag into its neighbour on the patch.

    Parameters
    ----------
    index : int
        0 to ``len(alphabet)**2 - 1``.
    alphabet : str

    Returns
    -------
    str
        Two characters; the first is the underlined one.

    Raises
    ------
    HandcapError
        When ``index`` is past the last tag.
    """
    n = len(check_alphabet(alphabet))
    if not 0 <= index < n * n:
        raise HandcapError(f"tag {index}: the alphabet {alphabet!r} makes only {n * n} tags; a session that needs "
                           "more takes a longer alphabet (--alphabet) or fewer patches")
    a, b = index % n, index // n
    return alphabet[a] + alphabet[(a + b) % n]


def tag_index(text: str, alphabet: str = ALPHABET) -> int:
    """The number of tag ``text`` in ``alphabet`` (the inverse of :func:`tag`).

    Parameters
    ----------
    text : str
        Two glyphs of ``alphabet``.
    alphabet : str

    Returns
    -------
    int

    Raises
    ------
    HandcapError
        When ``text`` is not two glyphs of the alphabet.
    """
    n = len(check_alphabet(alphabet))
    if len(text) != 2 or text[0] not in alphabet or text[1] not in alphabet:
        raise HandcapError(f"tag {text!r}: not two glyphs of the alphabet {alphabet!r}")
    a, c = alphabet.index(text[0]), alphabet.index(text[1])
    return a + n * ((c - a) % n)
