"""Multi-camera geometry: triangulation of markers seen by calibrated cameras (issue 6, in progress)."""

from handcap.multiview.triangulation import Triangulation, triangulate_linear, triangulate_ransac

__all__ = ["Triangulation", "triangulate_linear", "triangulate_ransac"]
