"""Viterbi recursion over a trellis of hypotheses (Forney 1973, doi:10.1109/PROC.1973.9030).

The labeler calls :func:`viterbi_step` once per frame (its transition scores
depend on the path so far, through the Kalman filters) and :func:`backtrack`
to decide a frame; :func:`viterbi_path` runs both over a fixed trellis.
Scores are log-probabilities.
"""

from __future__ import annotations

import numpy as np


def viterbi_step(previous, transition, emission) -> tuple[np.ndarray, np.ndarray]:
    """One frame of the recursion.

    Parameters
    ----------
    previous : ndarray (P,)
        Best path score ending in each state of the frame before.
    transition : ndarray (P, N)
        Score of going from state p to state n.
    emission : ndarray (N,)
        Score of each state of this frame.

    Returns
    -------
    scores : ndarray (N,)
        Best path score ending in each state.
    back : ndarray (N,) int
        The state of the frame before on that path.
    """
    total = np.asarray(previous)[:, None] + np.asarray(transition)
    back = np.argmax(total, axis=0)
    return np.asarray(emission) + total[back, np.arange(total.shape[1])], back


def backtrack(backs, last: int) -> list[int]:
    """States of the best path, oldest first, from the backpointers of each later frame and the last state.

    ``backs[i]`` maps the states of frame i + 1 to those of frame i.

    Parameters
    ----------
    backs : sequence of ndarray (N_t+1,) int
        Backpointers of frames 1 .. F-1 (:func:`viterbi_step`'s ``back``), oldest first.
    last : int
        State of the last frame on the path.

    Returns
    -------
    list of int
        One state per frame, F in all, oldest first.
    """
    path = [int(last)]
    for back in reversed(backs):
        path.append(int(back[path[-1]]))
    return path[::-1]


def viterbi_path(emissions, transitions) -> tuple[list[int], float]:
    """Best state sequence of a trellis and its score.

    Parameters
    ----------
    emissions : sequence of ndarray (N_t,)
    transitions : sequence of ndarray (N_t, N_t+1)
        One fewer than ``emissions``.
    """
    scores = np.asarray(emissions[0], dtype=np.float64)
    backs = []
    for transition, emission in zip(transitions, emissions[1:]):
        scores, back = viterbi_step(scores, transition, emission)
        backs.append(back)
    last = int(np.argmax(scores))
    return backtrack(backs, last), float(scores[last])
