"""Objects: rigid 6-DoF tracking from markers."""

from handcap.objects.rigid import RigidTrack, canonical_from_markers, kabsch, ransac_kabsch, track_rigid

__all__ = ["RigidTrack", "canonical_from_markers", "kabsch", "ransac_kabsch", "track_rigid"]
