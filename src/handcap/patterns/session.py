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

Tags are handed out in order, right hand first, so a session's tags are unique
and the same session always gets the same tags.
"""

from __future__ import annotations

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


def session_pattern(hands=HANDS, objects=("cuboid", "cylinder", "sphere", "cube2x2"), *, alphabet: str = ALPHABET,
                    pitch: float = PITCH, font: str = "DejaVu Sans Mono Bold") -> Pattern:
    """The template of a session: the 19 patches of each hand, then every object's patches.

    Parameters
    ----------
    hands : sequence of {'right', 'left'}
        Hands that wear patches.
    objects : sequence of str
        Names from :data:`OBJECT_PATCHES`.
    alphabet : str
        Glyphs of the tags.
    pitch : float
        Side of a square, metres.
    font : str
        Name of the printed font, for the record.

    Returns
    -------
    Pattern

    Raises
    ------
    HandcapError
        An unknown hand or object, or more white squares than the alphabet has tags.
    """
    hands, objects = tuple(hands), tuple(objects)
    for side in hands:
        if side not in HANDS:
            raise HandcapError(f"hand {side!r}: choose right or left")
    for name in objects:
        if name not in OBJECT_PATCHES:
            raise HandcapError(f"object {name!r}: choose from {', '.join(OBJECT_PATCHES)}")
    if len(set(hands)) != len(hands) or len(set(objects)) != len(objects):
        raise HandcapError("a hand or object is named twice; each one once")
    sizes = [(side, name, rows, cols, segment) for side in hands
             for name, (rows, cols, segment) in HAND_PATCHES.items()]
    sizes += [(obj, name, rows, cols, f"object:{obj}") for obj in objects
              for name, (rows, cols) in OBJECT_PATCHES[obj].items()]
    need = sum((rows * cols + 1) // 2 for _, _, rows, cols, _ in sizes)
    have = tag_count(alphabet)
    if need > have:
        raise HandcapError(f"this session has {need} white squares but the alphabet {alphabet!r} makes only {have} "
                           f"tags; use a longer alphabet (at least {int(need ** 0.5) + 1} glyphs) or fewer objects")
    counter = iter(range(have))

    def next_tag():
        return tag(next(counter), alphabet)

    patches = tuple(Patch(name, owner, segment, checker_tags(rows, cols, next_tag))
                    for owner, name, rows, cols, segment in sizes)
    return Pattern(patches, alphabet, float(pitch), font)
