"""Objects: rigid 6-DoF tracking from markers; articulated objects described by TOML (parts, revolute joints,
a puzzle cube's layers) and the 2x2x2 cube's moves (:mod:`~handcap.objects.cube`)."""

from handcap.objects.articulated import ArticulatedObject, Joint, Part, articulated_from_table, load_articulated
from handcap.objects.rigid import RigidTrack, canonical_from_markers, kabsch, ransac_kabsch, track_rigid

__all__ = ["ArticulatedObject", "Joint", "Part", "RigidTrack", "articulated_from_table", "canonical_from_markers",
           "kabsch", "load_articulated", "ransac_kabsch", "track_rigid"]
