"""rotjax: 3-D rotation maths in JAX, branch-free and differentiable everywhere it can be.

Pure functions on arrays, named `<source>_to_<target>` over quaternions (scalar last
`(x, y, z, w)`, Hamilton product), active rotation matrices (`v_world = R @ v_body`),
rotation vectors, axis-angle pairs and Euler angles (scipy's sequences: `"ZXZ"` intrinsic,
`"zxz"` extrinsic); kinematics (`frame="body"` or `"world"`) and fitting. Leading batch
dimensions broadcast; float32 and float64 are kept; every function works under `jax.jit`,
`jax.vmap` and `jax.grad`. The public functions are listed in `__all__`; the conventions,
gradient policy and guides are in the documentation (`docs/`).
"""

from . import manifold as manifold
from ._algebra import quaternion_canonical as quaternion_canonical
from ._algebra import quaternion_power as quaternion_power
from ._algebra import quaternion_reduce as quaternion_reduce
from ._algebra import rotation_group as rotation_group
from ._algebra import wahba_sensitivity as wahba_sensitivity
from ._davenport import davenport_to_quaternion as davenport_to_quaternion
from ._davenport import quaternion_to_davenport as quaternion_to_davenport
from ._euler import euler_to_matrix as euler_to_matrix
from ._euler import euler_to_quaternion as euler_to_quaternion
from ._euler import matrix_to_euler as matrix_to_euler
from ._euler import quaternion_to_euler as quaternion_to_euler
from ._fitting import align_vectors as align_vectors
from ._fitting import chordal_distance as chordal_distance
from ._fitting import geodesic_distance as geodesic_distance
from ._fitting import matrix_to_sixd as matrix_to_sixd
from ._fitting import nined_to_matrix as nined_to_matrix
from ._fitting import quaternion_mean as quaternion_mean
from ._fitting import sixd_to_matrix as sixd_to_matrix
from ._fitting import slerp as slerp
from ._interpolation import RotationSpline as RotationSpline
from ._interpolation import Slerp as Slerp
from ._matrix import matrix_to_quaternion as matrix_to_quaternion
from ._mrp import mrp_to_quaternion as mrp_to_quaternion
from ._mrp import quaternion_to_mrp as quaternion_to_mrp
from ._partition import partition_coordinates as partition_coordinates
from ._propagation import integrate_angular_velocity as integrate_angular_velocity
from ._propagation import (
    integrate_angular_velocity_samples as integrate_angular_velocity_samples,
)
from ._quaternion import angle_between as angle_between
from ._quaternion import quaternion_apply as quaternion_apply
from ._quaternion import quaternion_conjugate as quaternion_conjugate
from ._quaternion import quaternion_inverse as quaternion_inverse
from ._quaternion import quaternion_multiply as quaternion_multiply
from ._quaternion import quaternion_normalize as quaternion_normalize
from ._quaternion import quaternion_to_matrix as quaternion_to_matrix
from ._quaternion import relative_rotation as relative_rotation
from ._quaternion import rotation_angle as rotation_angle
from ._rates import (
    angular_acceleration_to_euler_accelerations as angular_acceleration_to_euler_accelerations,
)
from ._rates import angular_velocity_to_euler_rates as angular_velocity_to_euler_rates
from ._rates import (
    angular_velocity_to_matrix_derivative as angular_velocity_to_matrix_derivative,
)
from ._rates import (
    euler_accelerations_to_angular_acceleration as euler_accelerations_to_angular_acceleration,
)
from ._rates import euler_rate_matrix as euler_rate_matrix
from ._rates import euler_rates_to_angular_velocity as euler_rates_to_angular_velocity
from ._rates import euler_singularity as euler_singularity
from ._rates import (
    matrix_derivative_to_angular_velocity as matrix_derivative_to_angular_velocity,
)
from ._rates import quaternion_derivative as quaternion_derivative
from ._rates import (
    quaternion_derivative_to_angular_velocity as quaternion_derivative_to_angular_velocity,
)
from ._rigid import RigidTransform as RigidTransform
from ._rigid import normalize_dual_quaternion as normalize_dual_quaternion
from ._rotation import Rotation as Rotation
from ._rotvec import axis_angle_to_quaternion as axis_angle_to_quaternion
from ._rotvec import matrix_to_rotvec as matrix_to_rotvec
from ._rotvec import quaternion_to_axis_angle as quaternion_to_axis_angle
from ._rotvec import quaternion_to_rotvec as quaternion_to_rotvec
from ._rotvec import rotvec_to_matrix as rotvec_to_matrix
from ._rotvec import rotvec_to_quaternion as rotvec_to_quaternion
from ._se3 import hat as hat
from ._se3 import se3_adjoint as se3_adjoint
from ._se3 import se3_exp as se3_exp
from ._se3 import se3_left_jacobian as se3_left_jacobian
from ._se3 import se3_left_jacobian_inverse as se3_left_jacobian_inverse
from ._se3 import se3_log as se3_log
from ._se3 import se3_right_jacobian as se3_right_jacobian
from ._se3 import se3_right_jacobian_inverse as se3_right_jacobian_inverse
from ._se3 import so3_left_jacobian as so3_left_jacobian
from ._se3 import so3_left_jacobian_inverse as so3_left_jacobian_inverse
from ._se3 import so3_right_jacobian as so3_right_jacobian
from ._se3 import so3_right_jacobian_inverse as so3_right_jacobian_inverse
from ._se3 import vee as vee
from ._unwrap import unwrap_euler as unwrap_euler
from ._unwrap import unwrap_quaternion as unwrap_quaternion

__version__ = "0.1.0"

__all__ = [
    "RigidTransform",
    "Rotation",
    "RotationSpline",
    "Slerp",
    "align_vectors",
    "angle_between",
    "angular_acceleration_to_euler_accelerations",
    "angular_velocity_to_euler_rates",
    "angular_velocity_to_matrix_derivative",
    "axis_angle_to_quaternion",
    "chordal_distance",
    "davenport_to_quaternion",
    "euler_accelerations_to_angular_acceleration",
    "euler_rate_matrix",
    "euler_rates_to_angular_velocity",
    "euler_singularity",
    "euler_to_matrix",
    "euler_to_quaternion",
    "geodesic_distance",
    "hat",
    "integrate_angular_velocity",
    "integrate_angular_velocity_samples",
    "manifold",
    "matrix_derivative_to_angular_velocity",
    "matrix_to_euler",
    "matrix_to_quaternion",
    "matrix_to_rotvec",
    "matrix_to_sixd",
    "mrp_to_quaternion",
    "nined_to_matrix",
    "normalize_dual_quaternion",
    "partition_coordinates",
    "quaternion_apply",
    "quaternion_canonical",
    "quaternion_conjugate",
    "quaternion_derivative",
    "quaternion_derivative_to_angular_velocity",
    "quaternion_inverse",
    "quaternion_mean",
    "quaternion_multiply",
    "quaternion_normalize",
    "quaternion_power",
    "quaternion_reduce",
    "quaternion_to_axis_angle",
    "quaternion_to_davenport",
    "quaternion_to_euler",
    "quaternion_to_matrix",
    "quaternion_to_mrp",
    "quaternion_to_rotvec",
    "relative_rotation",
    "rotation_angle",
    "rotation_group",
    "rotvec_to_matrix",
    "rotvec_to_quaternion",
    "se3_adjoint",
    "se3_exp",
    "se3_left_jacobian",
    "se3_left_jacobian_inverse",
    "se3_log",
    "se3_right_jacobian",
    "se3_right_jacobian_inverse",
    "sixd_to_matrix",
    "slerp",
    "so3_left_jacobian",
    "so3_left_jacobian_inverse",
    "so3_right_jacobian",
    "so3_right_jacobian_inverse",
    "unwrap_euler",
    "unwrap_quaternion",
    "vee",
    "wahba_sensitivity",
]
