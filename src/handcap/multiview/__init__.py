"""Multi-camera geometry (DexterCap section 3): calibration, 2D detections, robust triangulation, cleaning."""

from handcap.multiview.boards import Board, BoardDetections, detect_board, detect_in_files, parse_board
from handcap.multiview.calibration import (BundleAdjustment, Intrinsics, RigCalibration, bundle_adjust,
                                          calibrate_intrinsics, calibrate_rig)
from handcap.multiview.clean import (CleanReport, MarkerGroups, clean_markers, fill_linear, fill_rigid, fill_spline,
                                    layout_groups, remove_cluster_outliers, remove_window_outliers)
from handcap.multiview.detections import Detections, merge_detections, read_detections, write_detections
from handcap.multiview.reconstruct import TriangulatedMarkers, quality_path, triangulate_detections, write_quality
from handcap.multiview.triangulation import Triangulation, triangulate_linear, triangulate_ransac

__all__ = ["Detections", "TriangulatedMarkers", "Triangulation", "merge_detections", "quality_path", "read_detections",
           "triangulate_detections", "triangulate_linear", "triangulate_ransac", "write_detections", "write_quality"]
__all__ += ["CleanReport", "MarkerGroups", "clean_markers", "fill_linear", "fill_rigid", "fill_spline",
            "layout_groups", "remove_cluster_outliers", "remove_window_outliers"]
__all__ += ["Board", "BoardDetections", "BundleAdjustment", "Intrinsics", "RigCalibration", "bundle_adjust",
            "calibrate_intrinsics", "calibrate_rig", "detect_board", "detect_in_files", "parse_board"]
