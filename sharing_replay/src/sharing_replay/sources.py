"""What a bag offers the replay, per robot: its scan topic, its trigger and plan topics, and every robot
of the bag with its base frame and recorded footprint (for the fleet-robot exclusion). Names only:
nothing here reads a message."""
from sharing_replay.errors import InputError, MissingTopicError
from sharing_replay.other_robots import FOOTPRINT_TOPIC

TRIGGER_TOPICS = {"stuck_feedback": "stuck_feedback", "recovery_status": "move_base/recovery_status"}


def source_topic(ns, name):
    return "/" + "/".join(p for p in (ns.strip("/"), name.strip("/")) if p)


def source_frame(ns, name):
    return "/".join(p for p in (ns.strip("/"), name.strip("/")) if p)


def robot_name_of(ns, single_name):
    """The handler's naming: namespace without slashes, nested a/b -> a_b."""
    ns = ns.strip("/")
    return ns.replace("/", "_") if ns else single_name


def discover_robots(topics, settings, every_namespace=False):
    """{namespace: scan topic} of the LaserScan topics that match settings.scan_topic (all of them with
    every_namespace, else those --robots picks).

    Raises InputError listing what the bag has when nothing matches (missing topic)."""
    scans = {t: typ for t, (typ, _n) in topics.items() if typ == "sensor_msgs/LaserScan"}
    wanted = settings.scan_topic
    found = {}
    if wanted.startswith("/"):
        if wanted in scans:
            found[wanted.rsplit("/", 1)[0].strip("/")] = wanted
    else:
        suffix = "/" + wanted.strip("/")
        for topic in scans:
            if topic.endswith(suffix):
                found[topic[: -len(suffix)].strip("/")] = topic
    if every_namespace:
        return found
    if settings.robots:
        missing = [r for r in settings.robots if r.strip("/") not in found]
        if missing:
            raise MissingTopicError("no %s topic for robot namespace(s) %s; LaserScan topics in the bag: %s"
                             % (wanted, ", ".join(missing), ", ".join(sorted(scans)) or "none"))
        found = {r.strip("/"): found[r.strip("/")] for r in settings.robots}
    if not found:
        raise MissingTopicError("missing topic: no sensor_msgs/LaserScan topic matches %r; LaserScan topics in "
                         "the bag: %s (choose one with --scan-topic)" % (wanted, ", ".join(sorted(scans)) or "none"))
    return found


def find_other_robots(topics, settings):
    """({robot name: base frame}, {footprint topic: robot name}) of every robot of the bag: each namespace
    with a scan topic (whatever --robots picks) or a recorded footprint."""
    everyone = set(discover_robots(topics, settings, every_namespace=True))
    suffix = "/" + FOOTPRINT_TOPIC
    footprints = {}
    for topic, (typ, _n) in topics.items():
        if typ == "geometry_msgs/PolygonStamped" and (topic == suffix or topic.endswith(suffix)):
            ns = topic[: -len(suffix)].strip("/")
            everyone.add(ns)
            footprints[topic] = robot_name_of(ns, settings.single_robot_name)
    frames = {robot_name_of(ns, settings.single_robot_name): source_frame(ns, settings.base_frame) for ns in everyone}
    return frames, footprints


def find_triggers(robots, topics, settings, start_time):
    """Trigger, plan and --trigger-at sources per robot: (trigger topics {topic: (robot, kind)}, plan topics
    {topic: robot}, timed triggers [(bag time, robot)] sorted, {robot name: [sources]}, missing topics).

    With --trigger auto a robot may legitimately have none (it was never sent a goal, or its move_base
    never failed): the summary says so, nothing is missing. A trigger asked for by name and absent is."""
    robots = list(robots)
    trigger_topics, plan_topics, sources, missing = {}, {}, {}, []
    kinds = {"auto": ("stuck_feedback", "recovery_status"), "both": ("stuck_feedback", "recovery_status"),
             "stuck_feedback": ("stuck_feedback",), "recovery_status": ("recovery_status",),
             "none": ()}[settings.trigger]
    for robot in robots:
        found = sources.setdefault(robot.name, [])
        for kind in kinds:
            topic = source_topic(robot.ns, TRIGGER_TOPICS[kind])
            if topic in topics:
                trigger_topics[topic] = (robot, kind)
                found.append(topic)
            elif settings.trigger != "auto":
                missing.append(topic)
    by_name = {r.name: r for r in robots}
    timed = []
    for name, t in settings.trigger_at:
        if name is None:
            targets = robots
        elif name in by_name:
            targets = [by_name[name]]
        else:
            raise InputError("--trigger-at names robot %r; robots in the bag: %s" % (name, ", ".join(sorted(by_name))))
        for robot in targets:
            timed.append((start_time + t, robot))
            sources[robot.name].append("--trigger-at %g" % t)
    timed.sort(key=lambda item: item[0])
    for robot in robots:
        for name in settings.plan_topics:
            topic = source_topic(robot.ns, name)
            if topic in topics:
                plan_topics[topic] = robot
                sources[robot.name].append(topic)
    return trigger_topics, plan_topics, timed, sources, missing
