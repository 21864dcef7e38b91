"""Reference frames: rotations (quaternion/DCM/ZYX Euler, ENU/FLU <-> NED/FRD) and WGS-84 geodesy.

``frames`` depends on NumPy only and on nothing else of ours; readers, the simulator and
preprocessing convert through these functions so there is exactly one tested conversion.
"""

from pipeline.frames.geodesy import (
    R_MEAN,
    WGS84_A,
    WGS84_B,
    WGS84_E2,
    WGS84_F,
    ecef_to_geodetic,
    ecef_to_ned,
    flat_earth_error,
    flat_earth_error_bound,
    flat_earth_error_model,
    flat_earth_to_ned,
    geodetic_to_ecef,
    geodetic_to_ned,
    ned_to_ecef,
    ned_to_flat_earth,
    ned_to_geodetic,
    radii_of_curvature,
    wrap_deg,
)
from pipeline.frames.rotations import (
    dcm_to_euler,
    dcm_to_quat,
    enu_to_ned,
    euler_to_dcm,
    euler_to_quat,
    flu_to_frd,
    frd_to_flu,
    ned_to_enu,
    quat_conj,
    quat_continuity,
    quat_enu_flu_to_ned_frd,
    quat_multiply,
    quat_ned_frd_to_enu_flu,
    quat_normalize,
    quat_rotate,
    quat_rotate_inverse,
    quat_slerp,
    quat_to_dcm,
    quat_to_euler,
)

__all__ = [
    "R_MEAN", "WGS84_A", "WGS84_B", "WGS84_E2", "WGS84_F",
    "ecef_to_geodetic", "ecef_to_ned", "flat_earth_error", "flat_earth_error_bound", "flat_earth_error_model",
    "flat_earth_to_ned", "geodetic_to_ecef", "geodetic_to_ned", "ned_to_ecef",
    "ned_to_flat_earth", "ned_to_geodetic", "radii_of_curvature", "wrap_deg",
    "dcm_to_euler", "dcm_to_quat", "enu_to_ned", "euler_to_dcm", "euler_to_quat", "flu_to_frd",
    "frd_to_flu", "ned_to_enu", "quat_conj", "quat_continuity", "quat_enu_flu_to_ned_frd",
    "quat_multiply", "quat_ned_frd_to_enu_flu", "quat_normalize", "quat_rotate",
    "quat_rotate_inverse", "quat_slerp", "quat_to_dcm", "quat_to_euler",
]
