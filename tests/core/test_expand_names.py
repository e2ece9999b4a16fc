"""Marker names and patterns shared by every verb (``handcap.core.markers.expand_names``)."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.core.markers import MarkerSequence, expand_names

NAMES = ["Hand:hand_top", "Hand:index_tip", "Hand:index_middle", "boite:c1", "boite:c2", "thumb_tip"]


@pytest.mark.parametrize("request_, expected", [
    ("index_tip", ["Hand:index_tip"]),                                    # prefix ignored
    ("Hand:index_tip", ["Hand:index_tip"]),                               # or given
    ("thumb_tip, index_tip", ["thumb_tip", "Hand:index_tip"]),            # order asked
    ("index_*", ["Hand:index_tip", "Hand:index_middle"]),                 # pattern on the unprefixed part
    ("boite:*", ["boite:c1", "boite:c2"]),                                # pattern on the whole name
    ("Hand:*", ["Hand:hand_top", "Hand:index_tip", "Hand:index_middle"]),
    ("index_tip,index_*", ["Hand:index_tip", "Hand:index_middle"]),       # each once
    (["c2", "c[1]"], ["boite:c2", "boite:c1"]),                           # a list of names and patterns
])
def test_names_and_patterns(request_, expected):
    assert expand_names(NAMES, request_) == expected


def test_a_marker_sequence_gives_its_names():
    markers = MarkerSequence(np.zeros((2, len(NAMES), 3)), NAMES, 100.0)
    assert expand_names(markers, "c1,hand_top") == ["boite:c1", "Hand:hand_top"]


@pytest.mark.parametrize("request_, message", [
    ("pinky_tip", "no marker named 'pinky_tip'; markers are: Hand:hand_top"),
    ("ring_*", "no marker matches 'ring_\\*'"),
    (" , ", "no marker names given"),
])
def test_unknown_names_are_one_line_errors(request_, message):
    with pytest.raises(HandcapError, match=message):
        expand_names(NAMES, request_)


def test_a_name_of_two_subjects_asks_for_the_prefix():
    with pytest.raises(HandcapError, match="'index_tip' is ambiguous: L:index_tip, R:index_tip; give the prefix"):
        expand_names(["L:index_tip", "R:index_tip"], "index_tip")
    assert expand_names(["L:index_tip", "R:index_tip"], "R:index_tip") == ["R:index_tip"]
