"""Anthropometric skeleton of the open hand model.

Everything the OpenHand skeleton is built from lives here, in one table, so the
build script (``tools/build_openhand.py``), the model and the tests read the
same numbers.

Sources
-------
* Segment lengths as proportions of hand length (HL), and the lateral positions
  of the carpometacarpal (CMC) joints as proportions of hand breadth (HB):
  Buchholz B., Armstrong T.J., Goldstein S.A. (1992) Anthropometric data for
  describing the kinematics of the human hand. Ergonomics 35(3):261-273,
  doi:10.1080/00140139208967812. The proportions sum along the middle finger
  to 1.001 HL, i.e. the chain runs from the wrist to the skin at the tip of the
  middle finger, which is how hand length is measured.
* Hand length and breadth of an average adult: British adults aged 19-65,
  50th percentile, men 190 mm / 87 mm, women 175 mm / 76 mm (Pheasant S.,
  Haslegrave C.M., Bodyspace, 3rd ed., CRC Press 2006, table 10.3). ``betas = 0``
  is their mean, 182.5 mm by 81.5 mm.
* Positions of the metacarpophalangeal (MCP) joints across the palm: the CMC
  positions above plus the lateral run of each metacarpal, as proportions of
  HB, following the reading of Buchholz's table in the hand model of
  Sancho-Bru et al. (2003), doi:10.1016/S0021-9290(03)00109-0.

Design choices (not from a table, stated so they can be argued with)
--------------------------------------------------------------------
* All CMC and MCP joint centres of the four fingers lie in the palm plane
  (y = 0); the flat hand has straight fingers with a light natural spread.
* The thumb CMC sits 0.09 HB palmar of the palm plane, inside the thenar
  eminence; the flat thumb points 40 degrees radially and 20 degrees palmar at
  the metacarpal, 25 and 10 degrees at the phalanges.

Coordinates (right hand): origin at the wrist joint centre, +x distal (towards
the middle finger's MCP), +y dorsal (back of the hand), +z ulnar (towards the
little finger). The left hand is the mirror image in z.
"""

from __future__ import annotations

import numpy as np

#: Average adult hand length and breadth in metres (Pheasant & Haslegrave 2006).
HAND_LENGTH = 0.5 * (0.190 + 0.175)
HAND_BREADTH = 0.5 * (0.087 + 0.076)

FINGERS = ("index", "middle", "pinky", "ring", "thumb")  # MANO order
#: Segment lengths / HL (Buchholz et al. 1992): metacarpal, proximal, middle, distal.
#: The thumb has metacarpal, proximal, distal. Distal segments end at the fingertip.
SEGMENT_RATIOS = {
    "thumb": (0.251, 0.196, 0.158),
    "index": (0.374, 0.265, 0.143, 0.097),
    "middle": (0.373, 0.277, 0.170, 0.108),
    "ring": (0.336, 0.259, 0.165, 0.107),
    "pinky": (0.295, 0.206, 0.117, 0.093),
}
#: Distance of the CMC joints distal of the wrist joint, / HL (Buchholz et al. 1992).
CMC_DISTAL_RATIO = 0.073
#: Radial offset of the CMC joints from the middle finger's axis, / HB (Buchholz et al. 1992).
CMC_RADIAL_RATIO = {"thumb": 0.196, "index": 0.126, "middle": 0.0, "ring": -0.129, "pinky": -0.223}
#: Radial offset of the MCP joints, / HB (CMC offset plus the metacarpal's lateral run).
MCP_RADIAL_RATIO = {"index": 0.252, "middle": 0.0, "ring": -0.206, "pinky": -0.393}
#: Palmar depth of the thumb CMC joint below the palm plane, / HB (design choice).
THUMB_CMC_PALMAR_RATIO = 0.09
#: Flat-hand directions (degrees): radial azimuth in the palm plane, palmar elevation.
FINGER_AZIMUTH_DEG = {"index": 6.0, "middle": 0.0, "ring": -7.0, "pinky": -14.0}
THUMB_AZIMUTH_DEG = (40.0, 25.0, 25.0)
THUMB_PALMAR_DEG = (20.0, 10.0, 10.0)


def _direction(azimuth_deg: float, palmar_deg: float = 0.0) -> np.ndarray:
    """Unit vector (x distal, y dorsal, z ulnar) pointing distally, turned radially and palmarly."""
    az, el = np.deg2rad(azimuth_deg), np.deg2rad(palmar_deg)
    return np.array([np.cos(el) * np.cos(az), -np.sin(el), -np.cos(el) * np.sin(az)])


def rest_skeleton(hand_length: float = HAND_LENGTH, hand_breadth: float = HAND_BREADTH) -> dict:
    """Joint centres of the flat right hand (metres, model coordinates).

    Parameters
    ----------
    hand_length : float
        Wrist to the tip of the middle finger, metres (default: the adult mean, :data:`HAND_LENGTH`).
    hand_breadth : float
        Across the MCP joints, metres (default :data:`HAND_BREADTH`).

    Returns
    -------
    dict
        ``"cmc"``: {finger: ndarray (3,)} carpometacarpal joints, metres (the
        thumb's is a MANO joint; the other fingers' are inside the rigid palm);
        ``"chain"``: {finger: ndarray (4, 3)}, metres: the MANO joints 1-3 of
        the finger followed by its tip. For fingers these are MCP, PIP, DIP,
        tip; for the thumb CMC, MCP, IP, tip.
    """
    hl, hb = float(hand_length), float(hand_breadth)
    cmc, chain = {}, {}
    for finger in ("index", "middle", "ring", "pinky"):
        metacarpal, *phalanges = np.array(SEGMENT_RATIOS[finger]) * hl
        cmc_point = np.array([CMC_DISTAL_RATIO * hl, 0.0, -CMC_RADIAL_RATIO[finger] * hb])
        lateral = -(MCP_RADIAL_RATIO[finger] - CMC_RADIAL_RATIO[finger]) * hb
        mcp = cmc_point + np.array([np.sqrt(max(metacarpal**2 - lateral**2, 0.0)), 0.0, lateral])
        step = _direction(FINGER_AZIMUTH_DEG[finger])
        points = [mcp]
        for length in phalanges:
            points.append(points[-1] + length * step)
        cmc[finger] = cmc_point
        chain[finger] = np.array(points)
    lengths = np.array(SEGMENT_RATIOS["thumb"]) * hl
    thumb_cmc = np.array([CMC_DISTAL_RATIO * hl, -THUMB_CMC_PALMAR_RATIO * hb, -CMC_RADIAL_RATIO["thumb"] * hb])
    points = [thumb_cmc]
    for length, az, el in zip(lengths, THUMB_AZIMUTH_DEG, THUMB_PALMAR_DEG):
        points.append(points[-1] + length * _direction(az, el))
    cmc["thumb"] = thumb_cmc
    chain["thumb"] = np.array(points)
    return {"cmc": cmc, "chain": chain}


def rest_joints(hand_length: float = HAND_LENGTH, hand_breadth: float = HAND_BREADTH):
    """The 16 MANO joints and 5 tips of the flat right hand.

    Parameters
    ----------
    hand_length : float
        Wrist to the tip of the middle finger, metres.
    hand_breadth : float
        Across the MCP joints, metres.

    Returns
    -------
    joints : ndarray (16, 3)
        Wrist, then index, middle, pinky, ring, thumb x 3 (MANO order), metres.
    tips : ndarray (5, 3)
        Tips of thumb, index, middle, ring, pinky (the File-contract order), metres.
    """
    chain = rest_skeleton(hand_length, hand_breadth)["chain"]
    joints = [np.zeros(3)]
    for finger in FINGERS:
        joints.extend(chain[finger][:3])
    tips = np.array([chain[f][3] for f in ("thumb", "index", "middle", "ring", "pinky")])
    return np.array(joints), tips


def segment_lengths_table(hand_length: float = HAND_LENGTH) -> dict:
    """Expected joint-to-joint lengths (metres) per finger, from the table.

    For the four fingers: proximal (MCP-PIP), middle (PIP-DIP), distal (DIP-tip);
    for the thumb: metacarpal (CMC-MCP), proximal (MCP-IP), distal (IP-tip).
    """
    out = {}
    for finger, ratios in SEGMENT_RATIOS.items():
        out[finger] = tuple(r * hand_length for r in (ratios if finger == "thumb" else ratios[1:]))
    return out
