"""What a move_base client sends: one place that turns (x, y, yaw) into a MoveBaseGoal."""
import rospy
from move_base_msgs.msg import MoveBaseGoal

from fleet_sim.frames import yaw_quaternion


def move_base_goal(x, y, yaw, frame_id="map"):
    """A MoveBaseGoal at (x, y) facing yaw in frame_id, stamped now."""
    goal = MoveBaseGoal()
    goal.target_pose.header.frame_id = frame_id
    goal.target_pose.header.stamp = rospy.Time.now()
    pose = goal.target_pose.pose
    pose.position.x, pose.position.y = x, y
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = yaw_quaternion(yaw)
    return goal
