"""Rendered scenes shared by the detector's tests (rendering is the slow part)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import SimpleNamespace

import numpy as np
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


@dataclass(frozen=True)
class SquareTake:
    """A synthetic take's 2D detections as ``handcap detect`` would write them, for naming unread squares.

    ``blocks``: every (tag, camera, frame, corners (4, 2) in reading order, their detection rows) a camera sees
    whole.
    """

    capture: object
    pattern: object
    names: np.ndarray
    blocks: list
    frames: int
    rate: float

    def without(self, unread_blocks):
        """The detections file's arrays with ``unread_blocks`` (indices into ``blocks``) left unread: their rows and
        block rows out, their corners given back as unread squares (turned and reversed in turn)."""
        from handcap.detect.naming import UnreadSquares

        d = self.capture.detections
        hidden = {r for k in unread_blocks for r in self.blocks[k][4]}
        keep = np.array([k not in hidden for k in range(len(d["frame"]))])
        kept = [b for k, b in enumerate(self.blocks) if k not in set(unread_blocks)]
        arrays = {"camera_names": d["camera_names"], "marker_names": self.names, "frame": d["frame"][keep],
                  "camera": d["camera"][keep], "marker": d["marker"][keep], "xy": d["xy"][keep],
                  "score": d["score"][keep], "rate": np.array(self.rate), "n_frames": np.array(self.frames),
                  "block_text": np.array([b[0] for b in kept], dtype="<U2"),
                  "block_camera": np.array([b[1] for b in kept], dtype=np.int64),
                  "block_frame": np.array([b[2] for b in kept], dtype=np.int64),
                  "block_xy": np.array([b[3] for b in kept]).reshape(-1, 4, 2), "block_score": np.ones(len(kept))}
        unread = []
        for j, k in enumerate(unread_blocks):
            xy = np.roll(self.blocks[k][3], j % 4, axis=0)
            xy = xy[::-1] if j % 2 else xy
            unread.append(UnreadSquares(self.blocks[k][1], self.blocks[k][2], xy[None], np.ones((1, 4))))
        return arrays, unread

    def unsynchronised(self, starts, every: int) -> SquareTake:
        """The take as cameras not triggered together film it: camera c's frame k is this take's frame
        ``starts[c] + every * k``, at ``rate / every``, so its offset against camera 0 is
        ``(starts[c] - starts[0]) / every`` frames."""
        d = self.capture.detections
        frames = (self.frames - 1 - max(starts)) // every + 1
        k, rest = np.divmod(d["frame"] - np.asarray(starts)[d["camera"]], every)
        keep = (rest == 0) & (k >= 0) & (k < frames)
        row = np.full(len(keep), -1)
        row[keep] = np.arange(keep.sum())
        kept = {**d, "frame": k[keep], **{key: d[key][keep] for key in ("camera", "marker", "xy", "score")}}
        blocks = [(tag, c, (f - starts[c]) // every, xy, list(row[rows])) for tag, c, f, xy, rows in self.blocks
                  if keep[rows].all()]
        return SquareTake(SimpleNamespace(detections=kept, rig=self.capture.rig), self.pattern, self.names, blocks,
                          frames, self.rate / every)


@lru_cache(maxsize=4)
def _square_take(rate: float, frames: int, cameras: int) -> SquareTake:
    from handcap.detect.naming import square_corners
    from handcap.patterns.session import session_pattern
    from handcap.synth.config import SynthConfig
    from handcap.synth.scene import synthesize

    capture = synthesize(SynthConfig(layout="dense-patches", motion="calibration", frames=frames, rate=rate, seed=8,
                                     cameras=cameras, outlier_rate=0.0, ghost_rate=0.0, swap_rate=0.0, dropout=0.0,
                                     pixel_noise=0.1, object="none"), progress=False)
    pattern = session_pattern(("right",), ())
    d = capture.detections
    names = np.array([f"right:{n}" for n in d["marker_names"]])
    tags, corners = square_corners(pattern, names)
    at = {(int(f), int(c), int(m)): k for k, (f, c, m) in enumerate(zip(d["frame"], d["camera"], d["marker"]))}
    blocks = []
    for f in range(frames):
        for c in range(cameras):
            for tag, ids in zip(tags, corners):
                rows = [at.get((f, c, int(m))) for m in ids]
                if None not in rows:
                    blocks.append((str(tag), c, f, d["xy"][rows], rows))
    return SquareTake(capture, pattern, names, blocks, frames, rate)


@pytest.fixture(scope="session")
def square_take():
    """``square_take(rate, frames, cameras)``: a calibration take of ``handcap synth`` (dense patches, pixel noise
    0.1 px, no wrong ids) as :class:`SquareTake`."""
    return _square_take
