"""Sensor noise: how much an image holds, and taking it down to what the detector's networks learned.

The networks learned rendered images whose sensor noise is at most about :data:`NOISE_LEARNED` grey levels
(:class:`handcap.synth.images.ImageStyle`: read noise 0.5-3 levels, shot noise 0.25 sqrt(level), so 5 at full
white). A camera at high gain in dim light gives more, and the corners and glyphs of small squares drown in
it. Measured on rendered hands (16 scenes, seed 100, full-size cameras, the shipped networks and checker;
2026-11-30), tags read right with noise of sigma 6 and 12 grey levels added: 69.7 and 42.1 % (80.1 % without
noise); denoised first as :func:`denoised` does, 75.8 and 69.7 %. On photographed sheets (8, seed 21) sigma 8
and 14 gave 70.3 and 30.6 % (3 tags read wrong), denoised 79.2 and 64.5 % (none wrong); 87.8 % without noise,
unchanged by the denoising. A Gaussian blur of 0.7 or 1 px lost 8-15 points on clean sheets and gained less on
noisy ones.

The noise is estimated with Immerkær's operator (the difference of two Laplacians, blind to flat, sloped and
curved grey), from the median of its magnitude over the image, so that the printed edges do not count: 1.7-4.2
grey levels on those clean rendered hands, 6.4-7.4 and 12.1-12.6 with noise of 6 and 12 added to them.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Most sensor noise the networks learned, grey levels of 255 (sigma; module docstring). Images that hold more are
#: denoised before the search.
NOISE_LEARNED = 5.0


def noise_sigma(image: np.ndarray) -> float:
    """The sensor noise an image holds: the standard deviation of white noise that gives its operator response.

    Parameters
    ----------
    image : ndarray (H, W)
        Grey uint8 image (at least 3 x 3 pixels).

    Returns
    -------
    float
        Sigma, grey levels of 255: the median magnitude of Immerkær's operator over the image (sampled at every
        fourth row and every other column: 7 ms for a 5 MP frame), which is 0.6745 times 6 sigma for Gaussian
        noise. 0 for anything but a grey uint8 image of 3 x 3 pixels or more (the detector refuses those itself).
    """
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 2 or min(image.shape) < 3:
        return 0.0
    # The operator at every fourth row and every other column is as good a sample (a few hundred thousand pixels
    # of a frame) at an eighth of the work. Integer weights on uint8: the response is a whole number (at most
    # 16 x 255), so its median comes from counts.
    rows = [image[k:len(image) - 2 + k:4].astype(np.int16) for k in range(3)]  # each row's two below it
    response = sum(w * (r[:, :-2:2] - 2 * r[:, 1:-1:2] + r[:, 2::2]) for w, r in zip((1, -2, 1), rows))
    counts = np.bincount(np.abs(response).ravel())
    median = int(np.searchsorted(np.cumsum(counts), (counts.sum() + 1) / 2))
    return median / (0.6745 * 6.0)


def denoised(image: np.ndarray, sigma: float) -> np.ndarray:
    """The image with its sensor noise taken down by non-local means (OpenCV's, its strength ``sigma``).

    Parameters
    ----------
    image : ndarray (H, W) uint8
    sigma : float
        The image's noise (:func:`noise_sigma`), grey levels.

    Returns
    -------
    ndarray (H, W) uint8
        About a second for a 5 MP frame on 2 cores.
    """
    return cv2.fastNlMeansDenoising(np.ascontiguousarray(image), None, h=float(sigma), templateWindowSize=5,
                                    searchWindowSize=11)
