"""handcap.hand.attachment: the marker attachment's subsets."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.hand.attachment import MarkerAttachment


def test_an_attachment_subset_names_the_unknown_marker():
    att = MarkerAttachment(("a", "b"), [0, 1], [[1.0, 0, 0], [0, 1.0, 0]], [0.005, 0.005], np.zeros(10))
    assert att.subset(["b"]).marker_names == ("b",)
    with pytest.raises(HandcapError, match="no marker 'c'; it holds a, b"):
        att.subset(["b", "c"])
