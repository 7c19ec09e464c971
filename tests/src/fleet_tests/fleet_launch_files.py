"""The fleet launch's files the benches read (fleet_launch's launch and config folders) and its arguments'
defaults. A shell without the workspace on its paths gets one line saying what to do, not a rospkg traceback."""
import os
import sys
import xml.etree.ElementTree as ET

import rospkg

WORKSPACE_MISSING = "the workspace is not on this shell's paths (%s): run 'make build', then 'source scripts/env.sh'"


def fleet_launch_path(*parts):
    """A path inside the fleet_launch package; ends the program with WORKSPACE_MISSING when it is not found."""
    try:
        root = rospkg.RosPack().get_path("fleet_launch")
    except rospkg.ResourceNotFound:
        sys.exit("%s: package fleet_launch not found: %s" % (os.path.basename(sys.argv[0]),
                                                            WORKSPACE_MISSING % "ROS_PACKAGE_PATH"))
    return os.path.join(root, *parts)


def launch_defaults(launch="fleet.launch"):
    """{arg name: default} of one of fleet_launch's launch files, as written there."""
    path = fleet_launch_path("launch", launch)
    return {a.get("name"): a.get("default") for a in ET.parse(path).getroot().iter("arg")
            if a.get("default") is not None}
