"""The coded-patch detector (DexterCap Sec. 3.2-3.3): from camera images to named 2D corners.

:mod:`~handcap.detect.corners` (the corner heatmap network), :mod:`~handcap.detect.blocks`
(white squares from corners), :mod:`~handcap.detect.reader` (the block reader network),
:mod:`~handcap.detect.voting` (tags fixed over the template, corners named),
:mod:`~handcap.detect.noise` (noisy images denoised first), :mod:`~handcap.detect.pipeline` (all of it on one
image), :mod:`~handcap.detect.adapt` (the reader fine-tuned on a take read without a template),
:mod:`~handcap.detect.sources` (frames from folders, videos, images), :mod:`~handcap.detect.networks` (weights
files) and :mod:`~handcap.detect.train` / :mod:`~handcap.detect.scenes` (training from rendered images).
The patches themselves are :mod:`handcap.patterns`. The networks load torch, so this package
imports nothing on its own: ``from handcap.detect.pipeline import Detector``.
"""
