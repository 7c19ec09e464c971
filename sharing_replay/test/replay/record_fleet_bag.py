#!/usr/bin/python3
"""Records the fleet bag that test_replay_fleet_bag.py replays: the README's fleet
(`roslaunch fleet_launch fleet.launch robots:=5 layout:=corridors record:=true`), every robot sent at
once to its goal in the top hall (the fleet benchmark's goals) with `move_base_simple/goal`, as a user
would send one. The short corridor is closed by a block that is not in the map: the robots drive
into it one behind the other, the first to see the block shares it, the others plan around it; on
the way they see each other, which the live fleet never shares (each layer excludes the robots its
bridge hears of).

  source scripts/env.sh
  unshare -n bash -c 'ip link set lo up && source scripts/env.sh && \\
      /usr/bin/python3 sharing_replay/test/replay/record_fleet_bag.py /tmp/fleet5.bag'

Then the bag is cut to what the replay and the test read (--keep-seconds of simulated time from the
start; the topics in KEEP_TOPICS) and compressed (bz2). Progress goes to stderr. It starts its own
master on a free port and its own ROS_HOME (the broker logins are made there), and stops them.
"""
import argparse
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

import yaml

# What the replay reads (scans, tf, map, plans, footprints) and what the test compares with (what each
# live handler sent to the fleet, and the simulator's ground truth).
KEEP_TOPICS = r"^(/robot_\d+/(base_scan|base_pose_ground_truth|to_fleet|move_base/NavfnROS/plan|" \
              r"move_base/global_costmap/footprint)|/tf|/tf_static|/map)$"


HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_WORLD = os.path.join(HERE, "data", "corridors_5_coarse.world")


def log(text):
    sys.stderr.write("record_fleet_bag: %s\n" % text)
    sys.stderr.flush()


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def fleet_launch_dir():
    import rospkg
    return rospkg.RosPack().get_path("fleet_launch")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", help="the bag to write (cut and compressed)")
    p.add_argument("--robots", type=int, default=5)
    p.add_argument("--layout", default="corridors", choices=("corridors", "facility", "deadend"))
    p.add_argument("--world", default=DEFAULT_WORLD,
                   help="Stage world (default: the fleet's corridors_5 with 271-beam lasers, %s); '' for the "
                        "launch's own" % os.path.relpath(DEFAULT_WORLD))
    p.add_argument("--launch", default="fleet.launch", choices=("fleet.launch", "move_base_fleet.launch"))
    p.add_argument("--speedup", type=float, default=1.0, help="fleet.launch speedup (default 1: real time)")
    p.add_argument("--seconds", type=float, default=20.0, help="simulated seconds recorded after the goals")
    p.add_argument("--keep-seconds", type=float, default=14.0,
                   help="simulated seconds from the bag's start kept in the cut bag")
    args = p.parse_args(argv)
    if not 1 <= args.robots <= 10:
        p.error("--robots must be 1..10, got %d" % args.robots)
    work = tempfile.mkdtemp(prefix="record_fleet_bag_")
    raw = os.path.join(work, "raw.bag")
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_HOME=os.path.join(work, "ros_home"),
               ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_IP="127.0.0.1", ROS_HOSTNAME="127.0.0.1")
    launch_args = ["robots:=%d" % args.robots, "layout:=%s" % args.layout, "record:=true", "bag:=" + raw]
    if args.world:
        launch_args.append("world:=" + os.path.abspath(args.world))
    if args.launch == "fleet.launch":
        launch_args.append("speedup:=%g" % args.speedup)
    log("roslaunch fleet_launch %s %s (master port %d, work folder %s)"
        % (args.launch, " ".join(launch_args), port, work))
    with open(os.path.join(work, "roslaunch.log"), "w") as launch_log:
        launch = subprocess.Popen(["roslaunch", "-p", str(port), "fleet_launch", args.launch] + launch_args,
                                  env=env, stdout=launch_log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        record(args, launch, raw)
    finally:
        if launch.poll() is None:
            os.killpg(launch.pid, signal.SIGINT)   # rosbag record closes the bag on SIGINT
            try:
                launch.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(launch.pid, signal.SIGKILL)
                launch.wait()
    if not os.path.isfile(raw):
        sys.exit("record_fleet_bag: no bag was written; see %s/roslaunch.log" % work)
    cut(raw, args.out, args.keep_seconds)
    shutil.rmtree(work, ignore_errors=True)
    log("wrote %s (%.2f MB)" % (args.out, os.path.getsize(args.out) / 1e6))


def record(args, launch, raw):
    import rospy
    from geometry_msgs.msg import PoseStamped
    deadline = time.monotonic() + 120
    import rosgraph
    while time.monotonic() < deadline:
        if launch.poll() is not None:
            sys.exit("record_fleet_bag: roslaunch ended (code %s) before the fleet was up" % launch.returncode)
        try:
            if rosgraph.Master("/record_fleet_bag").getParam("/use_sim_time"):
                break
        except Exception:  # master not up yet
            pass
        time.sleep(0.5)
    rospy.init_node("record_fleet_bag", disable_signals=True)
    with open(os.path.join(fleet_launch_dir(), "worlds", "%s_goals.yaml" % args.layout
                           if args.layout != "facility" else "goals.yaml")) as f:
        goals = yaml.safe_load(f)["bench_goals"]
    pubs = [rospy.Publisher("/robot_%d/move_base_simple/goal" % i, PoseStamped, queue_size=1, latch=True)
            for i in range(args.robots)]
    # Ready: every robot's navigation host listens for goals, and the recorder is writing.
    while time.monotonic() < deadline:
        if all(p.get_num_connections() > 0 for p in pubs) and os.path.exists(raw + ".active") \
                and rospy.get_time() > 0:
            break
        time.sleep(0.5)
    else:
        sys.exit("record_fleet_bag: the robots' move_base_simple/goal had no subscriber after 120 s")
    time.sleep(2.0)   # the recorder subscribes to topics as they appear
    start = rospy.get_time()
    for i, pub in enumerate(pubs):
        x, y, yaw = goals[i]
        goal = PoseStamped()
        goal.header.frame_id = "map"
        goal.header.stamp = rospy.Time.now()
        goal.pose.position.x, goal.pose.position.y = x, y
        goal.pose.orientation.w = 1.0
        pub.publish(goal)
        log("robot_%d sent to (%.1f, %.1f)" % (i, x, y))
    last = 0.0
    while rospy.get_time() - start < args.seconds:
        if launch.poll() is not None:
            sys.exit("record_fleet_bag: roslaunch ended (code %s) while recording" % launch.returncode)
        t = rospy.get_time() - start
        if t - last >= 10.0:
            last = t
            log("%.0f of %.0f simulated s" % (t, args.seconds))
        time.sleep(0.5)


def cut(raw, out, keep_seconds):
    """Copies the topics of KEEP_TOPICS up to keep_seconds after the start into out, bz2-compressed
    (messages as recorded: raw bytes and connection headers, so latching is kept)."""
    import rosbag
    keep = re.compile(KEEP_TOPICS)
    with rosbag.Bag(raw) as bag:
        end = bag.get_start_time() + keep_seconds
        topics = sorted(t for t in bag.get_type_and_topic_info().topics if keep.match(t))
        log("cutting to %.0f s and %d topics: %s" % (keep_seconds, len(topics), " ".join(topics)))
        tmp = out + ".part"
        with rosbag.Bag(tmp, "w", compression=rosbag.Compression.BZ2) as dst:
            for topic, msg, t, header in bag.read_messages(topics=topics, raw=True, return_connection_header=True):
                if t.to_sec() > end:
                    break
                dst.write(topic, msg, t, raw=True, connection_header=header)
    os.replace(tmp, out)


if __name__ == "__main__":
    main()
