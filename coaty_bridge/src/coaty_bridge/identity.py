"""Robot name <-> Coaty identity, for authenticated sources (issue 15, item 3).

With ``authenticate_sources`` a robot's Identity objectId (the sourceId of everything it
publishes) is not random but derived from its name: ``identity_for(namespace, robot)`` is a
UUID v5. The broker binds that id to credentials (username, or the CN of the client
certificate) and its ACL lets each login publish only under its own sourceId. A receiving
bridge then recomputes the id from an obstacle's ``source`` and drops the obstacle when it was
not published under that id: nobody can speak for another robot, and no directory of names is
needed on any robot.
"""
import uuid

from coaty_bridge.topics import check_name

#: Fixed namespace of the derived ids (any constant works; changing it renames every robot).
FLEET_ID_NAMESPACE = uuid.UUID("6f1c1ee5-0b43-4f5e-9f67-2a3d1c2b5e01")


def identity_for(namespace, robot_name):
    """The sourceId under which `robot_name` publishes in Coaty namespace `namespace`."""
    check_name(namespace, "namespace")
    check_name(robot_name, "robot name")
    return str(uuid.uuid5(FLEET_ID_NAMESPACE, "coaty-fleet/%s/%s" % (namespace, robot_name)))


def main(argv=None):
    """`python3 -m coaty_bridge.identity <namespace> <robot>...`: prints one line
    '<robot> <identity id>' each (the usernames / certificate CNs of a deployment)."""
    import sys
    args = sys.argv[1:] if argv is None else argv
    if len(args) < 2:
        print("usage: python3 -m coaty_bridge.identity <namespace> <robot_name>...", file=sys.stderr)
        return 2
    for robot in args[1:]:
        print("%s %s" % (robot, identity_for(args[0], robot)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
