"""Synthetic captures with ground truth, the yardstick of every other stage.

:mod:`~handcap.synth.scene` (:func:`~handcap.synth.scene.synthesize` and the capture folder),
:mod:`~handcap.synth.config` (the settings and ``scene.toml``), :mod:`~handcap.synth.motions`,
:mod:`~handcap.synth.objects`, :mod:`~handcap.synth.cameras` (the camera cage),
:mod:`~handcap.synth.visibility` (ray casting), :mod:`~handcap.synth.faults` (dropouts, ghosts, swaps) and
:mod:`~handcap.synth.render` (pictures).
"""
