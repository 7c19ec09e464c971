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

Plans keep ``clearance_margin`` metres more than the inscribed radius from obstacles where they can
(a second A* without the margin is the fallback): a passage only just wider than the robot in the
static map is closed by the first scan whose endpoints fall one cell in front of the mapped wall.

A blockage that made the robot stuck is remembered until the goal ends: the blocked (inscribed or
lethal) cells of the local window at that moment stay blocked for planning. Without this memory the
robot oscillates: the obstacle layer clears cells seen between ``obstacle_range`` and
``raytrace_range`` (costmap_2d semantics), so a robot that stops about obstacle_range before a
block and turns away erases part of its face, the next periodic replan runs through the block
again, and the robot reports the same blockage a second time.
"""
import enum
import logging
import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

from fleet_nav import nav_core as nav

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
        margin_cells = (params.inscribed_radius + params.clearance_margin) / costmap.geometry.resolution
        margin_cost = int(costmap.inflator.cost_at_distance(margin_cells)) if params.clearance_margin > 0 else 253
        self.margin_planner = (nav.GridPlanner(lethal_cost=max(1, min(253, margin_cost)),
                                               escape_cells=int(math.ceil(margin_cells)) + 1)
                               if planner is None and margin_cost < 253 else None)
        self.goal = None             # (x, y, yaw)
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.progress = 0
        self.failures = 0
        self.next_plan = None
        self.best_remaining = None   # shortest remaining plan length so far (progress check)
        self.last_progress_time = None
        self.stuck_count = 0         # stuck reports for the current goal
        self.final_rotation = False
        self.blockages = []          # (x0, y0, x1, y1, mask): remembered blocked cells, current goal
        self._footprint_edge = None  # footprint outline points (robot frame), for collision checks
        self.last_command = "none"   # what the controller did last, for failure messages
        self.stall_ref = None        # pose since which commands have not moved the robot
        self.stall_since = 0.0
        self.stall_turn = 0.0
        self.escapes = 0             # escapes from stalls so far (picks the next kind)
        self.escape_until = None
        self.escape_cmd = None

    # --- goals --------------------------------------------------------------------------------
    def set_goal(self, x, y, yaw, now):
        self.goal = (float(x), float(y), float(yaw))
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.progress = 0
        self.failures = 0
        self.stuck_count = 0
        self.blockages = []
        self.escape_until = None
        self.stall_ref = None
        self.next_plan = now
        self.best_remaining = None
        self.last_progress_time = now
        self.final_rotation = False

    def cancel(self):
        self.goal = None
        self.blockages = []
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
        status, path = self._make_plan(self.planning_costs(), start, goal)
        if status != nav.PlanStatus.OK:
            return False, nav.describe(status)
        self._set_path(path)
        return True, ""

    def _make_plan(self, costs, start, goal, window=None):
        """A* with the clearance margin, else without it."""
        if self.margin_planner is not None:
            status, path = self.margin_planner.make_plan(costs, start, goal, window)
            if status == nav.PlanStatus.OK:
                return status, path
        return self.planner.make_plan(costs, start, goal, window)

    def planning_costs(self):
        """The costmap with this goal's remembered blockages set to inscribed (never lowered)."""
        costs = self.costmap.costs
        if not self.blockages:
            return costs
        costs = costs.copy()
        for x0, y0, x1, y1, mask in self.blockages:
            sub = costs[y0:y1, x0:x1]
            sub[mask & (sub < 253)] = 253
        return costs

    def _remember_blockage(self, pose, window):
        """Keeps the blocked cells of the window searched for a way past for the rest of the goal."""
        cell = self.costmap.world_to_cell(pose[0], pose[1])
        if cell is None:
            return
        x0, y0, x1, y1 = window
        mask = self.costmap.costs[y0:y1, x0:x1] >= 253
        mask &= self.costmap.costs[y0:y1, x0:x1] != 255
        # The robot's own cells stay passable, so it can always plan away from the blockage.
        r = int(math.ceil(self.params.inscribed_radius * self._cells_per_metre()))
        cx, cy = cell[0] - x0, cell[1] - y0
        mask[max(0, cy - r):cy + r + 1, max(0, cx - r):cx + r + 1] = False
        self.blockages.append((x0, y0, x1, y1, mask))

    def _remaining(self):
        """Length of the plan from the robot's place on it to the goal, in metres."""
        pts = self.path_xy[self.progress:]
        if len(pts) < 2:
            return 0.0
        return float(np.hypot(*np.diff(pts, axis=0).T).sum())

    def _remember_plan_ahead(self, pose, metres=1.5):
        """After a failure to make progress: the plan's next metres (and the cells beside them)
        stay blocked for planning until the goal ends."""
        g = self.costmap.geometry
        pts = self.path_xy[self.progress:]
        if len(pts) == 0:
            return
        d = np.hypot(pts[:, 0] - pose[0], pts[:, 1] - pose[1])
        clear = self.params.inscribed_radius + g.resolution     # the robot's own cells stay free
        ahead = pts[(d > clear) & (d <= metres)]
        if len(ahead) == 0:
            return
        cells = np.array([self.costmap.world_to_cell(x, y) for x, y in ahead])
        x0, y0 = max(0, cells[:, 0].min() - 1), max(0, cells[:, 1].min() - 1)
        x1, y1 = min(g.size_x, cells[:, 0].max() + 2), min(g.size_y, cells[:, 1].max() + 2)
        mask = np.zeros((y1 - y0, x1 - x0), dtype=bool)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                mask[np.clip(cells[:, 1] - y0 + dy, 0, y1 - y0 - 1), np.clip(cells[:, 0] - x0 + dx, 0, x1 - x0 - 1)] = True
        self.blockages.append((x0, y0, x1, y1, mask))

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

    def _blocked_at(self, pose, distance):
        """Position in path of the first blocked cell ahead within distance metres of the robot,
        or -1; the robot's own start cells are skipped."""
        costs = self.costmap.costs
        flat = costs.reshape(-1)
        start = self.progress
        # A robot close to an obstacle starts in inscribed cells; those are not "ahead".
        while start < len(self.path) and flat[self.path[start]] >= 253 and flat[self.path[start]] != 255 \
                and start - self.progress < int(self.params.inscribed_radius * self._cells_per_metre()) + 2:
            start += 1
        count = int(distance * self._cells_per_metre() * 1.5) + 1
        blocked = nav.first_blocked(costs, self.path, start, count, 253)
        if blocked >= 0:
            bx, by = self.path_xy[blocked]
            if math.hypot(bx - pose[0], by - pose[1]) > distance:
                return -1
        return blocked

    def _way_past_window(self, pose, blocked_at):
        """The local window around the blocked cell, grown to contain the robot."""
        g = self.costmap.geometry
        start = self.costmap.world_to_cell(pose[0], pose[1])
        blocked = int(self.path[blocked_at])
        x0, y0, x1, y1 = self._window((blocked % g.size_x, blocked // g.size_x))
        return (min(x0, start[0]), min(y0, start[1]), max(x1, start[0] + 1), max(y1, start[1] + 1))

    def _window(self, cell):
        """The local window (local_window metres square) around a cell, clipped to the map."""
        g = self.costmap.geometry
        half = int(self.params.local_window / 2.0 * self._cells_per_metre())
        return (max(0, cell[0] - half), max(0, cell[1] - half),
                min(g.size_x, cell[0] + half + 1), min(g.size_y, cell[1] + half + 1))

    def _way_past(self, pose, blocked_at, window):
        """A path inside the window around the blockage, spliced into the global plan."""
        flat = self.costmap.costs.reshape(-1)
        g = self.costmap.geometry
        start = self.costmap.world_to_cell(pose[0], pose[1])
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
        status, local = self._make_plan(self.planning_costs(), start, (int(self.path[rejoin]) % g.size_x,
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
        # always reported as a failure, never silently planned around. When a replan is due the
        # check reaches as far as the robot's own marks can (half the local window), otherwise a
        # block seen 2-2.5 m ahead would be a silent replan or a stuck depending on timing.
        if len(self.path):
            self._update_progress(pose)
        replan_due = self.next_plan is not None and now >= self.next_plan
        reach = self.params.blocked_lookahead
        if replan_due:
            reach = max(reach, self.params.local_window / 2.0 - self.costmap.geometry.resolution)
        blocked = self._blocked_at(pose, reach) if len(self.path) else -1
        window = self._way_past_window(pose, blocked) if blocked >= 0 else None
        if blocked >= 0 and not self._way_past(pose, blocked, window):
            self.stuck_count += 1
            step.events.append(Event.STUCK)
            bx, by = self.path_xy[blocked]
            step.reason = ("path blocked at (%.2f, %.2f), %.2f m ahead, and no way past within the %.1f m "
                           "local window" % (bx, by, math.hypot(bx - pose[0], by - pose[1]),
                                             self.params.local_window))
            self._remember_blockage(pose, window)
            self.best_remaining = None
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

        # No progress for stuck_timeout seconds: the plan's remaining length did not shrink (pushing
        # against something unseen, or going back and forth in front of a gap the footprint does
        # not pass). The plan ahead is then remembered as blocked, so the replan takes another way.
        remaining = self._remaining()
        if self.best_remaining is None or remaining < self.best_remaining - 0.1:
            self.best_remaining = remaining
            self.last_progress_time = now
        elif now - self.last_progress_time > self.params.stuck_timeout:
            self.last_progress_time = now
            self.best_remaining = None
            reason = ("no progress for %.1f s at (%.2f, %.2f), %.1f m of plan left; last command %s"
                      % (self.params.stuck_timeout, pose[0], pose[1], remaining, self.last_command))
            self._remember_plan_ahead(pose)
            self.path = np.zeros(0, dtype=np.uint32)
            self.path_xy = np.zeros((0, 2))
            self.next_plan = now
            return self._fail(step, reason, now)
        elif remaining > self.best_remaining + 1.0 and now - self.last_progress_time < self.params.stuck_timeout / 4:
            # A replan onto a longer route while the robot was making progress (a shared obstacle
            # arrived) starts the count again; after a while without progress it is no excuse.
            self.best_remaining = remaining
            self.last_progress_time = now

        step.linear, step.angular = self._escape(now, pose) or self._follow(pose)
        self._watch_motion(now, pose, step.linear, step.angular)
        return step

    # Escapes, tried in turn on successive stalls: (linear, angular sign relative to the stalled turn).
    ESCAPES = (("turn the other way", 0.0, -1.0), ("creep forward", 0.15, 0.0), ("reverse", None, 0.0))

    def _watch_motion(self, now, pose, v, w):
        """Notices a stall: commands that move the robot, but for stall_time its pose did not change
        (the body touches something the footprint check on the costmap did not catch, e.g. a robot
        model larger than its configured footprint)."""
        moved = self.stall_ref is None or (math.hypot(pose[0] - self.stall_ref[0], pose[1] - self.stall_ref[1]) > 0.02
                                           or abs(_wrap(pose[2] - self.stall_ref[2])) > 0.05)
        if moved or (v == 0.0 and w == 0.0) or self.escape_until is not None:
            self.stall_ref, self.stall_since, self.stall_turn = pose, now, w
            return
        if now - self.stall_since < self.params.stall_time:
            return
        kind, lin, sign = self.ESCAPES[self.escapes % len(self.ESCAPES)]
        self.escapes += 1
        lin = -abs(self.params.escape_vel) if lin is None else lin
        ang = sign * math.copysign(min(1.0, self.params.max_rotational_vel), self.stall_turn or 1.0)
        self.escape_cmd = (kind, lin, ang)
        self.escape_until = now + self.params.stall_time
        LOG.info("stalled at (%.2f, %.2f) for %.1f s with %s; escape %d: %s for %.1f s", pose[0], pose[1],
                 now - self.stall_since, self.last_command, self.escapes, kind, self.params.stall_time)

    def _escape(self, now, pose):
        """The escape command while one runs, then a replan; None when not escaping."""
        if self.escape_until is None:
            return None
        if now >= self.escape_until:
            self.escape_until = None
            self.next_plan = now
            self.stall_ref = None
            return None
        kind, lin, ang = self.escape_cmd
        if self._collides(pose, lin, ang):
            return 0.0, 0.0
        self.last_command = "escape: %s (%.2f m/s, %.2f rad/s)" % (kind, lin, ang)
        return lin, ang

    def _follow(self, pose):
        """Pure pursuit towards the path point lookahead metres ahead; turn in place when far off.

        Pure pursuit cuts corners, and the path only keeps the robot's centre off inscribed cells:
        each command is checked by rolling the footprint forward ``collision_horizon`` seconds on
        the costmap; a command that would touch a lethal cell becomes a turn in place, or a slow
        reverse (like base_local_planner's escape_vel), or a stop.
        """
        pts = self.path_xy[self.progress:]
        d = np.hypot(pts[:, 0] - pose[0], pts[:, 1] - pose[1])
        ahead = np.nonzero(d >= self.params.lookahead)[0]
        target = pts[ahead[0]] if len(ahead) else pts[-1]
        heading = math.atan2(target[1] - pose[1], target[0] - pose[0])
        err = _wrap(heading - pose[2])
        w = max(-self.params.max_rotational_vel, min(self.params.max_rotational_vel, 2.0 * err))
        if abs(err) > 0.7:
            v = 0.0
        else:
            remaining = self.distance_to_goal(pose)
            v = self.params.max_vel_x * (1.0 - 0.6 * abs(err) / 0.7)
            v = min(v, max(0.1, 0.8 * remaining))
            # Slow down before a sharp bend of the path, so the robot turns where the path turns
            # instead of overshooting into the corner beyond it.
            near = np.nonzero(d >= 0.3)[0]
            far = np.nonzero(d >= 1.2)[0]
            if len(near) and len(far):
                a, b = pts[near[0]], pts[far[0]]
                bend = _wrap(math.atan2(b[1] - a[1], b[0] - a[0]) - math.atan2(a[1] - pose[1], a[0] - pose[0]))
                if abs(bend) > 0.6:
                    v = min(v, max(0.15, 0.4 * self.params.max_vel_x))
        wmax = self.params.max_rotational_vel
        # Nearest free command to the pursuit one: same speed with more or less turn, then slower.
        steer = sorted({max(-wmax, min(wmax, w + dw)) for dw in (0.0, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0)},
                       key=lambda c: abs(c - w))
        candidates = [("follow", v, w)] if v == 0.0 else \
            [("follow" if c == w else "steer", lin, c) for lin in (v, min(v, 0.15)) for c in steer]
        candidates += [("turn in place", 0.0, w), ("escape", -abs(self.params.escape_vel), 0.0)]
        for kind, cand_v, cand_w in candidates:
            # A turn in place is not held back by the outline check: it cannot take the centre
            # closer to anything, and a configured footprint larger than the body (the tutorials'
            # 0.46 m nose on Stage's PR2) would otherwise freeze the robot in every tight junction.
            # If the body does touch, the stall escape takes over.
            if cand_v == 0.0 or not self._collides(pose, cand_v, cand_w):
                self.last_command = "%s (%.2f m/s, %.2f rad/s)" % (kind, cand_v, cand_w)
                return cand_v, cand_w
        self.last_command = "stop: following (%.2f, %.2f), turning and reversing would all touch an obstacle" % (v, w)
        return 0.0, 0.0

    def _collides(self, pose, v, w):
        """Whether the footprint, driven at (v, w) for collision_horizon seconds, meets a lethal cell."""
        if self._footprint_edge is None:
            pts = np.asarray(self.params.footprint_polygon, dtype=float)
            step = self.costmap.geometry.resolution / 2.0
            edge = []
            for (x0, y0), (x1, y1) in zip(pts, np.roll(pts, -1, axis=0)):
                n = max(1, int(math.ceil(math.hypot(x1 - x0, y1 - y0) / step)))
                t = np.arange(n) / n
                edge.append(np.column_stack((x0 + t * (x1 - x0), y0 + t * (y1 - y0))))
            self._footprint_edge = np.concatenate(edge)
        costs = self.costmap.costs
        g = self.costmap.geometry
        x, y, yaw = pose
        dt = self.params.collision_horizon / 4.0
        # Step 0 is the pose itself: a robot already touching a lethal cell (a mark on its own
        # outline) is not held back by it, any command may take it out.
        for k in range(5):
            if k:
                x, y, yaw = x + v * math.cos(yaw) * dt, y + v * math.sin(yaw) * dt, yaw + w * dt
            c, s = math.cos(yaw), math.sin(yaw)
            px = x + c * self._footprint_edge[:, 0] - s * self._footprint_edge[:, 1]
            py = y + s * self._footprint_edge[:, 0] + c * self._footprint_edge[:, 1]
            cx = np.floor((px - g.origin_x) / g.resolution).astype(np.int64)
            cy = np.floor((py - g.origin_y) / g.resolution).astype(np.int64)
            inside = (cx >= 0) & (cy >= 0) & (cx < g.size_x) & (cy < g.size_y)
            hit = not inside.all() or bool((costs[cy[inside], cx[inside]] == 254).any())
            if hit:
                return k > 0
        return False
