"""The demo behind `python -m rotjax`: worked examples from Nikravesh (1988), converted every
way."""

from __future__ import annotations

import numpy as np

# Kamman, "Conversion of Direction Cosines to Euler Parameters", Example 1: 350 deg about
# (2, -3, 6)/7. Its [R] is a passive direction-cosine matrix (N components -> body components),
# i.e. the transpose of rotjax's active matrix. Values as printed (6 digits).
KAMMAN_DCM_350 = np.array(
    [
        [0.986048, -0.150702, -0.070700],
        [0.146981, 0.987598, -0.055195],
        [0.078141, 0.044033, 0.995969],
    ]
)
# Example 2: -250 deg about the same axis.
KAMMAN_DCM_M250 = np.array(
    [
        [-0.232467, 0.641122, 0.731383],
        [-0.969780, -0.095527, -0.224503],
        [-0.074067, -0.761471, 0.643954],
    ]
)
KAMMAN_AXIS = np.array([2.0, -3.0, 6.0]) / 7.0


def _vec(x, decimals: int = 5) -> str:
    """A vector with fixed decimals, every entry 9 wide: rows of the demo line up."""
    return "[" + " ".join(f"{v:9.{decimals}f}" for v in np.ravel(np.asarray(x, float))) + " ]"


def _row(label: str, text: str) -> None:
    print(f"  {label:<34}{text}")


def main(argv: list[str] | None = None) -> int:
    import rotjax as rj

    print(f"rotjax {rj.__version__}: conventions: active matrices (v_world = R @ v_body),")
    print("quaternions scalar last (x, y, z, w), Hamilton product, w >= 0 from matrices.")
    print("Unit quantities to 5 decimals, degrees to 3 (the DCMs are given to 6 digits).\n")
    for name, dcm, deg in (
        ("Example 1 (350 deg)", KAMMAN_DCM_350, 350.0),
        ("Example 2 (-250 deg)", KAMMAN_DCM_M250, -250.0),
    ):
        print(f"Kamman {name} about (2, -3, 6)/7")
        q = rj.matrix_to_quaternion(dcm.T)  # passive DCM -> active matrix: transpose
        _row("Euler parameters from the DCM", _vec(q))
        q_true = rj.axis_angle_to_quaternion(KAMMAN_AXIS, deg, degrees=True)
        _row("from axis-angle (same up to sign)", _vec(q_true))
        axis, angle = rj.quaternion_to_axis_angle(q, degrees=True)
        _row("axis", _vec(axis))
        _row("angle [deg]", f" {float(angle):9.3f}")
        _row("rotation vector [deg]", _vec(rj.matrix_to_rotvec(dcm.T, True), 3))
        for seq in ("ZXZ", "XYZ", "zyx"):
            ang = rj.matrix_to_euler(dcm.T, seq, degrees=True)
            _row(f"Euler {seq} [deg]", _vec(ang, 3))
        print()
    # Nikravesh Eq. A.1: A = D C B for Euler angles (psi, theta, sigma), intrinsic z-x-z.
    angles = np.array([0.3, 1.1, -0.7])
    print(f"Nikravesh z-x-z Euler angles ({', '.join(f'{a:g}' for a in angles)}) rad:")
    for i, row in enumerate(np.asarray(rj.euler_to_matrix(angles, "313"))):
        _row("A (Eq. A.1)" if i == 0 else "", _vec(row))
    back = rj.matrix_to_euler(rj.euler_to_matrix(angles, "313"), "313")
    _row("and back [rad]", _vec(back))
    # Nikravesh Eq. A.5 at phi2 = pi/2: only phi1 + phi3 is defined (here 0.8 rad).
    s, c = np.sin(0.8), np.cos(0.8)
    lock = np.array([[0.0, 0.0, 1.0], [s, c, 0.0], [-c, s, 0.0]])
    print("\nBryant angles (intrinsic XYZ) at gimbal lock, phi1 + phi3 = 0.8:")
    ang = rj.matrix_to_euler(lock, "XYZ")
    _row("angles [rad] (third set to 0)", _vec(ang))
    err = np.abs(np.asarray(rj.euler_to_matrix(ang, "XYZ")) - lock).max()
    _row("round trip max |R - R(angles)|", f"{err:.1e}")
    return 0
