"""2-D rigid transforms (x, y, yaw) as plain tuples, and the map↔world alignment.

A transform ``T_a_b`` maps coordinates in frame b into frame a.
"""
import math


def yaw_quaternion(yaw):
    """The quaternion (x, y, z, w) of a rotation by yaw about z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def normalize_angle(a):
    """Angle wrapped into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def compose(t_ab, t_bc):
    """T_a_c = T_a_b * T_b_c."""
    x, y, th = t_ab
    c, s = math.cos(th), math.sin(th)
    return (x + c * t_bc[0] - s * t_bc[1], y + s * t_bc[0] + c * t_bc[1],
            normalize_angle(th + t_bc[2]))


def inverse(t_ab):
    """T_b_a from T_a_b."""
    x, y, th = t_ab
    c, s = math.cos(th), math.sin(th)
    return (-c * x - s * y, s * x - c * y, normalize_angle(-th))


def apply(t_ab, x, y):
    """A point in frame b expressed in frame a (works on NumPy arrays too)."""
    c, s = math.cos(t_ab[2]), math.sin(t_ab[2])
    return t_ab[0] + c * x - s * y, t_ab[1] + s * x + c * y


def world_from_map(floor_pose, floor_size, map_origin=(0.0, 0.0, 0.0)):
    """T_world_map: where a map_server map of a floorplan's bitmap lies in Stage's world.

    Stage scales the bitmap to ``floor_size`` and centres it on ``floor_pose``
    (x, y, yaw in radians); map_server puts the image's lower-left corner at
    ``map_origin``. Hence T_world_map = T_world_floor * T_floor_corner * T_map_corner^-1.
    For the Willow world (pose [-26.3 29.2 0 90], size 58.4 × 52.6, origin 0)
    this gives a pure +90° rotation: map (x, y) = world (y, -x).
    """
    corner = compose(floor_pose, (-floor_size[0] / 2.0, -floor_size[1] / 2.0, 0.0))
    return compose(corner, inverse(map_origin))
