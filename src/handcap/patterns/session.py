"""The patches a capture session prints: 19 per hand, and the faces of its objects.

Hand patches follow DexterCap (Sec. 3.1.2): one strip three squares wide on
the back of every phalanx, its rows along the bone and kept clear of the
joints, two patches on the dorsum and two on the palm. Their sizes
(:data:`HAND_PATCHES`) fit the average adult hand of handcap's template; the
``dense-patches`` layout places these grids on that hand and lists the corners
that lie on skin moving rigidly with their segment (``tools/make_layouts.py``);
the others are printed and detected too, but not solved for. Objects get one patch per face
(:data:`OBJECT_PATCHES`); the 2x2x2 cube one 4 x 4 patch on each of its 24
facelets (5 mm squares on 28 mm facelets, as in the paper's Appendix B).

Objects of a lab's own (a mug, a drill) get the patches their faces are given
(:func:`own_object`: ``mug=side:3x12,lid:3x3``). Tags are handed out in order,
right hand first, so a session's tags are unique and the same session always
gets the same tags. A session that is already printed is extended (``base``):
its patches keep their tags, and the new ones get tags it does not use, so a new
object joins patches already taped on without any of them being printed again.
"""

from __future__ import annotations

import re

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import ALPHABET, tag, tag_count
from handcap.patterns.pattern import PITCH, Patch, Pattern, checker_tags

#: Square rows x columns of each hand patch, and its segment.
HAND_PATCHES = {
    "thumb_proximal": (7, 3, "thumb_proximal"), "thumb_middle": (5, 3, "thumb_middle"),
    "thumb_distal": (4, 3, "thumb_distal"),
    "index_proximal": (8, 3, "index_proximal"), "index_middle": (3, 3, "index_middle"),
    "index_distal": (1, 3, "index_distal"),
    "middle_proximal": (8, 3, "middle_proximal"), "middle_middle": (4, 3, "middle_middle"),
    "middle_distal": (2, 3, "middle_distal"),
    "ring_proximal": (7, 3, "ring_proximal"), "ring_middle": (4, 3, "ring_middle"),
    "ring_distal": (2, 3, "ring_distal"),
    "pinky_proximal": (5, 3, "pinky_proximal"), "pinky_middle": (2, 3, "pinky_middle"),
    "pinky_distal": (1, 3, "pinky_distal"),
    "dorsum_proximal": (6, 9, "palm"), "dorsum_distal": (6, 9, "palm"),
    "palm_proximal": (5, 8, "palm"), "palm_distal": (4, 8, "palm"),
}
#: Patches of the standard objects (:mod:`handcap.synth.objects`): name -> (rows, cols).
OBJECT_PATCHES = {
    "cuboid": {face: (4, 4) for face in ("xp", "xn", "yp", "yn", "zp", "zn")},
    "cylinder": {"band": (3, 8), "top": (3, 3), "bottom": (3, 3)},
    "sphere": {f"cap{k}": (3, 3) for k in range(4)},
    "cube2x2": {f"{face}{k}": (4, 4) for face in "UDLRFB" for k in range(4)},
}
HANDS = ("right", "left")
_OWN = re.compile(r"^([A-Za-z0-9_.-]+)=(.+)$")
_FACE = re.compile(r"^([A-Za-z0-9_.-]+):(\d+)[xX](\d+)$")


def own_object(spec: str) -> tuple[str, dict[str, tuple[int, int]]]:
    """An object of the user's own and the patch of each of its faces, from ``NAME=FACE:RxC[,FACE:RxC...]``.

    Parameters
    ----------
    spec : str
        The object's name, ``=``, then its faces, comma-separated: a face's name, ``:``, and its patch's rows x
        columns of squares (``mug=side:3x12,lid:3x3``). Names take letters, digits, ``_``, ``.`` and ``-``.

    Returns
    -------
    name : str
    faces : dict
        Face name -> (rows, cols), in the order given.

    Raises
    ------
    HandcapError
        A spec not of that form, a face named twice, a patch of no squares, or a name a hand or a standard
        object already has.
    """
    whole = _OWN.match(spec.strip())
    if whole is None:
        raise HandcapError(f"object {spec!r}: give NAME=FACE:RxC[,FACE:RxC...], e.g. mug=side:3x12,lid:3x3 (rows x "
                           "columns of squares on each face)")
    name, faces = whole.group(1), {}
    if name in HANDS or name in OBJECT_PATCHES:
        raise HandcapError(f"object {name!r}: that name is a hand's or a standard object's; give yours another")
    for part in whole.group(2).split(","):
        face = _FACE.match(part.strip())
        if face is None:
            raise HandcapError(f"object {name}: face {part.strip()!r} is not FACE:RxC (e.g. side:3x12, rows x "
                               "columns of squares)")
        rows, cols = int(face.group(2)), int(face.group(3))
        if face.group(1) in faces:
            raise HandcapError(f"object {name}: face {face.group(1)!r} is given twice")
        if not (1 <= rows <= 200 and 1 <= cols <= 200):
            raise HandcapError(f"object {name}: face {face.group(1)} has {rows}x{cols} squares; give 1 to 200 each")
        faces[face.group(1)] = (rows, cols)
    return name, faces


def session_pattern(hands=HANDS, objects=("cuboid", "cylinder", "sphere", "cube2x2"), *, own=None,
                    alphabet: str = ALPHABET, pitch: float = PITCH, font: str = "DejaVu Sans Mono Bold",
                    base: Pattern | None = None) -> Pattern:
    """The template of a session: the 19 patches of each hand, then every object's patches.

    Parameters
    ----------
    hands : sequence of {'right', 'left'}
        Hands that wear patches.
    objects : sequence of str
        Names from :data:`OBJECT_PATCHES`.
    own : dict, optional
        Objects of the user's own, after the standard ones: name -> {face: (rows, cols)}, as :func:`own_object`
        gives them.
    alphabet : str
        Glyphs of the tags.
    pitch : float
        Side of a square, metres.
    font : str
        Name of the printed font, for the record.
    base : Pattern, optional
        A session already printed, to extend: the result holds its patches first, unchanged, and the new
        ones with tags it does not use (``alphabet`` and ``pitch`` must be its own).

    Returns
    -------
    Pattern

    Raises
    ------
    HandcapError
        An unknown hand or object, one that ``base`` already has, more white squares than the alphabet has
        tags, or another alphabet or pitch than ``base``'s.
    """
    hands, objects, own = tuple(hands), tuple(objects), dict(own or {})
    taken = set()
    if base is not None:
        if alphabet != base.alphabet or abs(pitch - base.pitch) > 1e-9:
            raise HandcapError(f"the session to extend is printed in the alphabet {base.alphabet!r} with "
                               f"{base.pitch * 1000:g} mm squares; its new patches must be too (give the same "
                               "--alphabet and --pitch, or none)")
        again = [o for o in (*hands, *objects, *own) if o in base.owners]
        if again:
            raise HandcapError(f"{again[0]!r} already has patches in the session to extend; to print them again use "
                               "--template")
        taken = set(base.tags)
    for side in hands:
        if side not in HANDS:
            raise HandcapError(f"hand {side!r}: choose right or left")
    for name in objects:
        if name not in OBJECT_PATCHES:
            raise HandcapError(f"object {name!r}: choose from {', '.join(OBJECT_PATCHES)}")
    for name in own:
        if name in HANDS or name in OBJECT_PATCHES:
            raise HandcapError(f"object {name!r}: that name is a hand's or a standard object's; give yours another")
    if len(set(hands)) != len(hands) or len(set(objects)) != len(objects):
        raise HandcapError("a hand or object is named twice; each one once")
    sizes = [(side, name, rows, cols, segment) for side in hands
             for name, (rows, cols, segment) in HAND_PATCHES.items()]
    sizes += [(obj, name, rows, cols, f"object:{obj}") for obj in objects
              for name, (rows, cols) in OBJECT_PATCHES[obj].items()]
    sizes += [(obj, name, rows, cols, f"object:{obj}") for obj, faces in own.items()
              for name, (rows, cols) in faces.items()]
    need = sum((rows * cols + 1) // 2 for _, _, rows, cols, _ in sizes) + len(taken)
    have = tag_count(alphabet)
    if need > have and taken:
        raise HandcapError(f"the session to extend uses {len(taken)} of the {have} tags of its alphabet and the new "
                           f"patches need {need - len(taken)} more; add fewer or smaller patches, or print a new "
                           "session with a longer alphabet")
    if need > have:
        raise HandcapError(f"this session has {need} white squares but the alphabet {alphabet!r} makes only {have} "
                           f"tags; use a longer alphabet (at least {int(need ** 0.5) + 1} glyphs) or fewer objects")
    free = (t for t in (tag(k, alphabet) for k in range(have)) if t not in taken)

    def next_tag():
        return next(free)

    patches = tuple(Patch(name, owner, segment, checker_tags(rows, cols, next_tag))
                    for owner, name, rows, cols, segment in sizes)
    return Pattern((base.patches if base is not None else ()) + patches, alphabet, float(pitch), font)
