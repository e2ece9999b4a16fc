"""Steps: one function per command of ``handcap``, from files to files.

Each reads its inputs (checking that no output would overwrite one), runs the
stage, writes its outputs atomically with their warnings, and returns a
:class:`~handcap.steps.step.Step` whose ``summary()`` the command line prints.
They are the layer that combines the stages: the command line only parses
arguments and calls them, and a session runner can chain them.

Modules: :mod:`~handcap.steps.markers` (convert, corrupt, fill), :mod:`~handcap.steps.markerless`
(keypoints, fit-keypoints, markerless), :mod:`~handcap.steps.markerless_demo` (demo --markerless),
:mod:`~handcap.steps.synth` (synth, demo), :mod:`~handcap.steps.solve`
(calibrate-markers, solve, shape), :mod:`~handcap.steps.objects` (track-object),
:mod:`~handcap.steps.metrics`, :mod:`~handcap.steps.label` (label, score-labels),
:mod:`~handcap.steps.occlusion` (train-occlusion), :mod:`~handcap.steps.multiview`
(triangulate, clean), :mod:`~handcap.steps.calibrate` (intrinsics, rig) and
:mod:`~handcap.steps.layout` (new, check).
"""

from handcap.steps.step import Step

__all__ = ["Step"]
