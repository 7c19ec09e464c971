"""Global planning, path following and stuck detection of fleet_nav, without ROS.

``Navigator.tick(now, pose)`` is called at controller_frequency with the robot's pose in the
costmap frame and returns a ``Step``: the velocity command and the events of this tick.
It plans with the C++ A* on the inflated costmap, replans every 1/planner_frequency seconds (so a
driving robot switches route when a shared obstacle arrives), and checks the path ahead
(``blocked_lookahead`` metres) against the current costmap on every tick. When the path ahead is
blocked it looks for a way past inside a ``local_window`` square around the robot (a windowed A*
to the first free path cell behind the blockage); only when there is none it counts a failure and
reports ``STUCK`` once, stops, and replans at once. ``max_failures`` failures (stuck, no global
plan, or no progress for ``stuck_timeout`` seconds) abort the goal.
"""
import enum
import logging
import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

from sharing_layer_cpp import nav

LOG = logging.getLogger(__name__)


class Event(enum.Enum):
    PLANNED = "planned"        # a new global plan (payload: the plan replaced the old one)
    STUCK = "stuck"            # path blocked, no way past in the local window: publish stuck_feedback
    SUCCEEDED = "succeeded"
    ABORTED = "aborted"


@dataclass
class Step:
    linear: float = 0.0
    angular: float = 0.0
    events: List[Event] = field(default_factory=list)
    reason: str = ""           # why, for ABORTED and STUCK


def _wrap(angle):
    return math.atan2(math.sin(angle), math.cos(angle))


class Navigator:
    """One goal at a time, like move_base. ``costmap`` needs ``costs`` (uint8 (size_y, size_x)),
    ``world_to_cell(x, y)`` and ``cell_to_world(indexes)``."""

    def __init__(self, params, costmap, planner=None):
        self.params = params
        self.costmap = costmap
        # A start in the inscribed zone may leave it through inscribed cells within the robot's radius.
        escape = int(math.ceil(params.inscribed_radius / costmap.geometry.resolution)) + 1
        self.planner = planner or nav.GridPlanner(escape_cells=escape)
        self.goal = None             # (x, y, yaw)
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.progress = 0
        self.failures = 0
        self.next_plan = None
        self.last_progress_pose = None
        self.last_progress_time = None
        self.stuck_count = 0         # stuck reports for the current goal
        self.final_rotation = False

    # --- goals --------------------------------------------------------------------------------
    def set_goal(self, x, y, yaw, now):
        self.goal = (float(x), float(y), float(yaw))
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.progress = 0
        self.failures = 0
        self.stuck_count = 0
        self.next_plan = now
        self.last_progress_pose = None
        self.last_progress_time = now
        self.final_rotation = False

    def cancel(self):
        self.goal = None
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))

    @property
    def active(self):
        return self.goal is not None

    def distance_to_goal(self, pose):
        if self.goal is None:
            return 0.0
        return math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1])

    # --- planning -----------------------------------------------------------------------------
    def plan(self, pose):
        """Global plan from pose to the goal; returns (ok, reason)."""
        start = self.costmap.world_to_cell(pose[0], pose[1])
        goal = self.costmap.world_to_cell(self.goal[0], self.goal[1])
        if start is None:
            return False, "the robot (%.2f, %.2f) is outside the costmap" % (pose[0], pose[1])
        if goal is None:
            return False, "the goal is outside the costmap"
        status, path = self.planner.make_plan(self.costmap.costs, start, goal)
        if status != nav.PlanStatus.OK:
            return False, nav.describe(status)
        self._set_path(path)
        return True, ""

    def _set_path(self, path):
        self.path = path
        self.path_xy = self.costmap.cell_to_world(path)
        if len(self.path_xy):
            # The last point is the goal itself, not its cell centre.
            self.path_xy[-1] = self.goal[:2]
        self.progress = 0

    def _update_progress(self, pose):
        """Index of the path point nearest the robot, searched a little ahead of the last one."""
        if len(self.path_xy) == 0:
            return
        hi = min(len(self.path_xy), self.progress + 200)
        seg = self.path_xy[self.progress:hi]
        d = np.hypot(seg[:, 0] - pose[0], seg[:, 1] - pose[1])
        self.progress += int(np.argmin(d))

    def _cells_per_metre(self):
        return 1.0 / self.costmap.geometry.resolution

    def _blocked_at(self):
        """Position in path of the first blocked cell ahead, skipping the robot's own start cells."""
        costs = self.costmap.costs
        flat = costs.reshape(-1)
        start = self.progress
        # A robot close to an obstacle starts in inscribed cells; those are not "ahead".
        while start < len(self.path) and flat[self.path[start]] >= 253 and flat[self.path[start]] != 255 \
                and start - self.progress < int(self.params.inscribed_radius * self._cells_per_metre()) + 2:
            start += 1
        count = int(self.params.blocked_lookahead * self._cells_per_metre() * 1.5) + 1
        return nav.first_blocked(costs, self.path, start, count, 253)

    def _way_past(self, pose, blocked_at):
        """A path inside the local window around the blockage, spliced into the global plan."""
        flat = self.costmap.costs.reshape(-1)
        g = self.costmap.geometry
        start = self.costmap.world_to_cell(pose[0], pose[1])
        half = int(self.params.local_window / 2.0 * self._cells_per_metre())
        window = (max(0, start[0] - half), max(0, start[1] - half),
                  min(g.size_x, start[0] + half + 1), min(g.size_y, start[1] + half + 1))
        rejoin = None
        for i in range(blocked_at + 1, len(self.path)):
            cell = int(self.path[i])
            x, y = cell % g.size_x, cell // g.size_x
            if not (window[0] <= x < window[2] and window[1] <= y < window[3]):
                break
            if flat[cell] < 253:
                rejoin = i
        if rejoin is None:
            return False
        status, local = self.planner.make_plan(self.costmap.costs, start, (int(self.path[rejoin]) % g.size_x,
                                                                           int(self.path[rejoin]) // g.size_x),
                                               window)
        if status != nav.PlanStatus.OK:
            return False
        spliced = np.concatenate((local, self.path[rejoin + 1:])).astype(np.uint32)
        self._set_path(spliced)
        return True

    def _fail(self, step, reason, now):
        self.failures += 1
        LOG.warning("failure %d of %d: %s", self.failures, self.params.max_failures, reason)
        if self.failures >= self.params.max_failures:
            step.events.append(Event.ABORTED)
            step.reason = "gave up after %d failures; last: %s" % (self.failures, reason)
            self.cancel()
        return step

    # --- control ------------------------------------------------------------------------------
    def tick(self, now, pose):
        """One control cycle; pose = (x, y, yaw) in the costmap frame."""
        step = Step()
        if self.goal is None:
            return step
        gx, gy, gyaw = self.goal
        if self.final_rotation or self.distance_to_goal(pose) <= self.params.xy_goal_tolerance:
            self.final_rotation = True
            err = _wrap(gyaw - pose[2])
            if abs(err) <= self.params.yaw_goal_tolerance:
                step.events.append(Event.SUCCEEDED)
                self.cancel()
                return step
            step.angular = math.copysign(max(0.3, min(self.params.max_rotational_vel, 1.5 * abs(err))), err)
            return step

        # The path ahead is checked before any periodic replan, so a blockage the robot runs into is
        # always reported as a failure, never silently planned around on the same tick.
        if len(self.path):
            self._update_progress(pose)
        blocked = self._blocked_at() if len(self.path) else -1
        if blocked >= 0 and not self._way_past(pose, blocked):
            self.stuck_count += 1
            step.events.append(Event.STUCK)
            bx, by = self.path_xy[blocked]
            step.reason = ("path blocked at (%.2f, %.2f), %.2f m ahead, and no way past within the %.1f m "
                           "local window" % (bx, by, math.hypot(bx - pose[0], by - pose[1]),
                                             self.params.local_window))
            self.path = np.zeros(0, dtype=np.uint32)
            self.path_xy = np.zeros((0, 2))
            self.next_plan = now      # replan at once on the next tick
            self.last_progress_time = now
            return self._fail(step, step.reason, now)

        if self.next_plan is not None and now >= self.next_plan:
            ok, reason = self.plan(pose)
            period = 1.0 / self.params.planner_frequency if self.params.planner_frequency > 0 else None
            if not ok:
                self.path = np.zeros(0, dtype=np.uint32)
                self.path_xy = np.zeros((0, 2))
                # Retry after a planner period (1 s when planning only on demand).
                self.next_plan = now + (period or 1.0)
                return self._fail(step, "no global plan: %s" % reason, now)
            step.events.append(Event.PLANNED)
            self.next_plan = now + period if period else None
        if len(self.path) == 0:
            return step

        # No progress for stuck_timeout seconds (e.g. pushing against something unseen).
        if self.last_progress_pose is None or math.hypot(pose[0] - self.last_progress_pose[0],
                                                         pose[1] - self.last_progress_pose[1]) > 0.1:
            self.last_progress_pose = pose
            self.last_progress_time = now
        elif now - self.last_progress_time > self.params.stuck_timeout:
            self.last_progress_time = now
            self.next_plan = now
            return self._fail(step, "no progress for %.1f s at (%.2f, %.2f)"
                              % (self.params.stuck_timeout, pose[0], pose[1]), now)

        step.linear, step.angular = self._follow(pose)
        return step

    def _follow(self, pose):
        """Pure pursuit towards the path point lookahead metres ahead; turn in place when far off."""
        pts = self.path_xy[self.progress:]
        d = np.hypot(pts[:, 0] - pose[0], pts[:, 1] - pose[1])
        ahead = np.nonzero(d >= self.params.lookahead)[0]
        target = pts[ahead[0]] if len(ahead) else pts[-1]
        heading = math.atan2(target[1] - pose[1], target[0] - pose[0])
        err = _wrap(heading - pose[2])
        w = max(-self.params.max_rotational_vel, min(self.params.max_rotational_vel, 2.0 * err))
        if abs(err) > 0.7:
            return 0.0, w
        remaining = self.distance_to_goal(pose)
        v = self.params.max_vel_x * (1.0 - 0.6 * abs(err) / 0.7)
        v = min(v, max(0.1, 0.8 * remaining))
        return v, w
