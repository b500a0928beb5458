"""Global 3D descriptors written after PCL 1.13: VFH, CVFH and CRH (with roll alignment), numpy in, numpy out.

All functions take clouds in the camera frame (x right, y down, z forward, camera at the origin), in metres.
"""

from asmteach.plugins.detectors.cvfh.descriptors.crh import compute_crh, crh_roll_candidates, roll_correlation
from asmteach.plugins.detectors.cvfh.descriptors.cvfh import CvfhParams, CvfhRegion, compute_cvfh
from asmteach.plugins.detectors.cvfh.descriptors.normals import estimate_normals_curvature
from asmteach.plugins.detectors.cvfh.descriptors.pairs import PairFeatures, pair_features
from asmteach.plugins.detectors.cvfh.descriptors.vfh import VFH_SIZE, compute_vfh

__all__ = [
    "VFH_SIZE",
    "CvfhParams",
    "CvfhRegion",
    "PairFeatures",
    "compute_crh",
    "compute_cvfh",
    "compute_vfh",
    "crh_roll_candidates",
    "estimate_normals_curvature",
    "pair_features",
    "roll_correlation",
]
