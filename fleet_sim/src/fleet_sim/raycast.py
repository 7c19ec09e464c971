"""The one place the simulator calls the project's C++ raycaster.

``raycast_ranges(grid, resolution, origin_x, origin_y, sensor_x, sensor_y, angles,
min_range, max_range) -> float32 ranges`` is ``sharing_layer_cpp.core.raycast_ranges``:
a cell != 0 blocks a ray; angles are absolute world angles; a ray that hits
nothing or leaves the grid reports ``max_range``.
"""


def core_raycaster():
    """The C++ core's raycast function; raises ImportError with a hint if it is not built."""
    try:
        from sharing_layer_cpp import core
    except ImportError as err:
        raise ImportError("fleet_sim needs the C++ raycaster 'sharing_layer_cpp.core' "
                          "(build the workspace and source devel/setup.bash): %s" % err) from err
    return core.raycast_ranges
