"""move_base's state machine for fleet_nav, without ROS.

``Navigator.tick(now, pose)`` is move_base's ``executeCycle``, called at controller_frequency
with the robot's pose in the costmap frame; it returns a ``Step``: the velocity command and the
events of this cycle. The states and transitions are move_base's (move_base.cpp, noetic):

- PLANNING: the global planner (A* on the inflated costmap) runs. A plan → CONTROLLING. No plan:
  retried every cycle until ``planner_patience`` seconds have passed since the last valid plan
  (or more than ``max_planning_retries`` retries, when that is >= 0) → CLEARING (trigger PLANNING).
- CONTROLLING: the local controller follows the plan; with ``planner_frequency`` > 0 the plan is
  replaced every 1/planner_frequency s (a failed replan keeps the old plan). The goal reached
  (xy and yaw tolerance) → SUCCEEDED. No valid command → PLANNING while less than
  ``controller_patience`` s have passed since the last valid command, else CLEARING (trigger
  CONTROLLING). No move of ``oscillation_distance`` for ``oscillation_timeout`` s (0 = off)
  → CLEARING (trigger OSCILLATION).
- CLEARING: the next recovery behaviour in move_base's default order (conservative_reset,
  rotate_recovery, aggressive_reset, rotate_recovery; rotations only with
  ``clearing_rotation_allowed``, none without ``recovery_behavior_enabled``) runs, announced
  by a RECOVERY event (the node publishes move_base's RecoveryStatus), then PLANNING. With no
  behaviour left the goal is ABORTED with move_base's text for the trigger. A valid plan (after a
  PLANNING trigger), a valid command (after a CONTROLLING trigger) or a move (after an
  OSCILLATION trigger) starts the recovery list again.

The local controller is our stand-in for base_local_planner: pure pursuit along the plan with
each command checked by rolling the footprint forward on the costmap (``_follow``). Its
computeVelocityCommands fails where base_local_planner's does: when the plan within its forward
simulation (``blocked_lookahead`` m, by default the local planner's sim_time x max_vel_x) runs
through an inscribed or lethal cell, or when no command is free of lethal cells. It also escapes
a stall (commands that do not move the robot: a Stage body that touches what the footprint check
did not see), which base_local_planner does with escape_vel.

move_base publishes no stuck_feedback. With ``stuck_feedback_on_local_failure`` (the thesis's
modified move_base) a failed computeVelocityCommands is reported as a STUCK event.
"""
import enum
import logging
import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

from fleet_nav import nav_core as nav

LOG = logging.getLogger(__name__)


class State(enum.Enum):
    PLANNING = "planning"
    CONTROLLING = "controlling"
    CLEARING = "clearing"


class RecoveryTrigger(enum.Enum):
    PLANNING = "planning"
    CONTROLLING = "controlling"
    OSCILLATION = "oscillation"


# move_base's words when it gives up (MoveBase::executeCycle, CLEARING state).
ABORT_TEXT = {
    RecoveryTrigger.CONTROLLING: "Failed to find a valid control. Even after executing recovery behaviors.",
    RecoveryTrigger.PLANNING: "Failed to find a valid plan. Even after executing recovery behaviors.",
    RecoveryTrigger.OSCILLATION: "Robot is oscillating. Even after executing recovery behaviors.",
}


class Event(enum.Enum):
    PLANNED = "planned"        # a new global plan
    STUCK = "stuck"            # computeVelocityCommands failed (published only in the thesis's mode)
    RECOVERY = "recovery"      # a recovery behaviour starts (Step.recovery says which)
    SUCCEEDED = "succeeded"
    ABORTED = "aborted"


@dataclass
class Step:
    linear: float = 0.0
    angular: float = 0.0
    events: List[Event] = field(default_factory=list)
    reason: str = ""           # why, for ABORTED and STUCK
    recovery: Optional[Tuple[int, int, str]] = None   # (index, total, name) with RECOVERY


@dataclass(frozen=True)
class RecoveryBehaviour:
    name: str
    kind: str                  # "clear" or "rotate"
    reset_distance: float = 0.0
    layer_names: Tuple[str, ...] = ()


def default_recovery_behaviours(params):
    """move_base's loadDefaultRecoveryBehaviors."""
    if not params.recovery_behavior_enabled:
        return []
    behaviours = [RecoveryBehaviour("conservative_reset", "clear", params.conservative_reset_dist,
                                    params.conservative_reset_layer_names)]
    if params.clearing_rotation_allowed:
        behaviours.append(RecoveryBehaviour("rotate_recovery", "rotate"))
    behaviours.append(RecoveryBehaviour("aggressive_reset", "clear", 4.0 * params.robot_extent,
                                        params.aggressive_reset_layer_names))
    if params.clearing_rotation_allowed:
        behaviours.append(RecoveryBehaviour("rotate_recovery", "rotate"))
    return behaviours


def _wrap(angle):
    return math.atan2(math.sin(angle), math.cos(angle))


class Navigator:
    """One goal at a time, like move_base. ``costmap`` needs ``costs`` (uint8 (size_y, size_x)),
    ``geometry``, ``inflator``, ``world_to_cell(x, y)``, ``cell_to_world(indexes)`` and
    ``clear_obstacles_outside(x, y, size, layer_names)``."""

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
        self.recovery_behaviours = default_recovery_behaviours(params)
        self.goal = None             # (x, y, yaw)
        self.state = State.PLANNING
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.progress = 0
        self.final_rotation = False
        self._footprint_edge = None  # footprint outline points (robot frame), for collision checks
        self.last_command = "none"   # what the controller did last, for failure messages
        self.stall_ref = None        # pose since which commands have not moved the robot
        self.stall_since = 0.0
        self.stall_turn = 0.0
        self.escapes = 0             # escapes from stalls so far (picks the next kind)
        self.escape_until = None
        self.escape_cmd = None
        self.wedged_at = None        # pose where every escape was blocked (until the robot moves)
        self._reset_state(0.0)

    def _reset_state(self, now):
        """move_base's resetState plus what a new goal sets."""
        self.state = State.PLANNING
        self.recovery_index = 0
        self.recovery_trigger = RecoveryTrigger.PLANNING
        self.planning_retries = 0
        self.last_valid_plan = now
        self.last_valid_control = now
        self.last_oscillation_reset = now
        self.oscillation_pose = None
        self.next_plan = now
        self.rotation = None         # a running rotate_recovery: (turned so far, last yaw)
        self.local_failures = 0      # failed computeVelocityCommands for this goal

    # --- goals --------------------------------------------------------------------------------
    def set_goal(self, x, y, yaw, now):
        self.goal = (float(x), float(y), float(yaw))
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.progress = 0
        self.escape_until = None
        self.stall_ref = None
        self.wedged_at = None
        self.final_rotation = False
        self._reset_state(now)

    def cancel(self):
        self.goal = None
        self.path = np.zeros(0, dtype=np.uint32)
        self.path_xy = np.zeros((0, 2))
        self.rotation = None

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
        status, path = self._make_plan(self.costmap.costs, start, goal)
        if status != nav.PlanStatus.OK:
            return False, nav.describe(status)
        self._set_path(path)
        return True, ""

    def _make_plan(self, costs, start, goal):
        """A* with the clearance margin, else without it."""
        if self.margin_planner is not None:
            status, path = self.margin_planner.make_plan(costs, start, goal)
            if status == nav.PlanStatus.OK:
                return status, path
        return self.planner.make_plan(costs, start, goal)

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

    # --- move_base's executeCycle -----------------------------------------------------------------
    def tick(self, now, pose):
        """One control cycle; pose = (x, y, yaw) in the costmap frame."""
        step = Step()
        if self.goal is None:
            return step
        p = self.params
        # Oscillation bookkeeping, every cycle as in move_base.
        if self.oscillation_pose is None or math.hypot(pose[0] - self.oscillation_pose[0],
                                                       pose[1] - self.oscillation_pose[1]) >= p.oscillation_distance:
            self.last_oscillation_reset = now
            self.oscillation_pose = pose
            if self.recovery_trigger is RecoveryTrigger.OSCILLATION:
                self.recovery_index = 0

        # A CLEARING state set during this cycle is acted on in the next one, as move_base's
        # planner thread and controller hand it over.
        clearing = self.state is State.CLEARING
        if self.state is State.PLANNING or (self.state is State.CONTROLLING and p.planner_frequency > 0
                                           and now >= self.next_plan):
            self._planner_cycle(step, now, pose)
        if self.state is State.CONTROLLING:
            self._control(step, now, pose)
        elif clearing:
            self._clear(step, now, pose)
        return step

    def _planner_cycle(self, step, now, pose):
        """move_base's planThread, run in the cycle instead of a thread of its own."""
        p = self.params
        if p.planner_frequency > 0:
            self.next_plan = now + 1.0 / p.planner_frequency
        ok, reason = self.plan(pose)
        if ok:
            self.last_valid_plan = now
            self.planning_retries = 0
            step.events.append(Event.PLANNED)
            if self.recovery_trigger is RecoveryTrigger.PLANNING:
                self.recovery_index = 0
            self.state = State.CONTROLLING
            return
        if self.state is not State.PLANNING:
            return                  # a failed periodic replan keeps the plan being followed
        self.planning_retries += 1
        out_of_retries = p.max_planning_retries >= 0 and self.planning_retries > p.max_planning_retries
        if now > self.last_valid_plan + p.planner_patience or out_of_retries:
            LOG.warning("no global plan for %.1f s (%d retries): %s; clearing", now - self.last_valid_plan,
                        self.planning_retries, reason)
            self.state = State.CLEARING
            self.recovery_trigger = RecoveryTrigger.PLANNING

    def _control(self, step, now, pose):
        p = self.params
        # The goal reached: base_local_planner's isGoalReached (position, then heading in place).
        if self.final_rotation or self.distance_to_goal(pose) <= p.xy_goal_tolerance:
            self.final_rotation = True
            err = _wrap(self.goal[2] - pose[2])
            if abs(err) <= p.yaw_goal_tolerance:
                step.events.append(Event.SUCCEEDED)
                self.cancel()
                return
            step.angular = math.copysign(max(0.3, min(p.max_rotational_vel, 1.5 * abs(err))), err)
            self.last_valid_control = now
            return
        if p.oscillation_timeout > 0 and now > self.last_oscillation_reset + p.oscillation_timeout:
            LOG.warning("no move of %.2f m for %.1f s at (%.2f, %.2f); clearing", p.oscillation_distance,
                        p.oscillation_timeout, pose[0], pose[1])
            self.state = State.CLEARING
            self.recovery_trigger = RecoveryTrigger.OSCILLATION
            return
        command, failure = self._compute_velocity(now, pose)
        if command is not None:
            step.linear, step.angular = command
            # Once every escape was blocked, a command counts as valid control only when the robot
            # has moved since: a wedged robot's turn in place must neither hold off
            # controller_patience nor start the recovery list again, or move_base's recoveries
            # (and at the end the abort) would never come.
            if self.wedged_at is not None and self._moved(self.wedged_at, pose):
                self.wedged_at = None
            if self.wedged_at is None:
                self.last_valid_control = now
                if self.recovery_trigger is RecoveryTrigger.CONTROLLING:
                    self.recovery_index = 0
            self._watch_motion(now, pose, step.linear, step.angular)
            return
        self.local_failures += 1
        if p.stuck_feedback_on_local_failure:
            step.events.append(Event.STUCK)
            step.reason = failure
        if now > self.last_valid_control + p.controller_patience:
            LOG.warning("no valid control for %.1f s: %s; clearing", now - self.last_valid_control, failure)
            self.state = State.CLEARING
            self.recovery_trigger = RecoveryTrigger.CONTROLLING
        else:
            LOG.info("the local controller failed (%s); replanning", failure)
            self.last_valid_plan = now
            self.planning_retries = 0
            self.state = State.PLANNING

    def _compute_velocity(self, now, pose):
        """computeVelocityCommands: (command, None), or (None, why it failed)."""
        if len(self.path) == 0:
            return None, "no plan to follow"
        self._update_progress(pose)
        blocked = self._blocked_at(pose, self.params.blocked_lookahead)
        if blocked >= 0:
            bx, by = self.path_xy[blocked]
            return None, ("the plan is blocked at (%.2f, %.2f), %.2f m ahead" % (bx, by, math.hypot(bx - pose[0],
                                                                                                      by - pose[1])))
        command = self._escape(now, pose)
        if command is self.NO_ESCAPE:
            return None, self.last_command
        command = command or self._follow(pose)
        if command is None:
            return None, self.last_command
        return command, None

    def _clear(self, step, now, pose):
        """The CLEARING state: one recovery behaviour, then PLANNING; or abort."""
        if self.rotation is not None:
            if self._rotate(step, pose):
                return
            self._recovered(now)
            return
        if self.recovery_index >= len(self.recovery_behaviours):
            step.events.append(Event.ABORTED)
            step.reason = ABORT_TEXT[self.recovery_trigger]
            LOG.error("aborting: %s (trigger %s)", step.reason, self.recovery_trigger.value)
            self.cancel()
            return
        behaviour = self.recovery_behaviours[self.recovery_index]
        step.events.append(Event.RECOVERY)
        step.recovery = (self.recovery_index, len(self.recovery_behaviours), behaviour.name)
        LOG.info("recovery behaviour %d of %d: %s (trigger %s)", self.recovery_index + 1,
                 len(self.recovery_behaviours), behaviour.name, self.recovery_trigger.value)
        if behaviour.kind == "clear":
            cleared = self.costmap.clear_obstacles_outside(pose[0], pose[1], behaviour.reset_distance,
                                                           behaviour.layer_names)
            LOG.info("%s: %d obstacle cells cleared outside %.2f m x %.2f m around (%.2f, %.2f)", behaviour.name,
                     cleared, behaviour.reset_distance, behaviour.reset_distance, pose[0], pose[1])
            self._recovered(now)
        else:
            self.rotation = (0.0, pose[2])
            if not self._rotate(step, pose):
                self._recovered(now)

    def _recovered(self, now):
        """After a recovery behaviour, as move_base: plan again and start the timers afresh."""
        self.rotation = None
        self.last_valid_plan = now
        self.last_oscillation_reset = now
        self.planning_retries = 0
        self.recovery_index += 1
        self.state = State.PLANNING

    def _rotate(self, step, pose):
        """rotate_recovery: a full turn in place; False when done or when turning would collide."""
        turned, last = self.rotation
        turned += abs(_wrap(pose[2] - last))
        self.rotation = (turned, pose[2])
        left = 2.0 * math.pi - turned
        if left <= self.params.yaw_goal_tolerance:
            return False
        p = self.params
        speed = min(p.max_rotational_vel, max(p.min_in_place_rotational_vel, math.sqrt(2.0 * p.acc_lim_th * left)))
        if self._collides(pose, 0.0, speed):
            LOG.warning("rotate_recovery stops after %.0f deg: turning further would touch an obstacle",
                        math.degrees(turned))
            return False
        step.linear, step.angular = 0.0, speed
        return True

    # Escapes, tried in turn on successive stalls: (linear, angular sign relative to the stalled turn).
    ESCAPES = (("turn the other way", 0.0, -1.0), ("creep forward", 0.15, 0.0), ("reverse", None, 0.0))
    NO_ESCAPE = "no escape"       # _escape's answer when every escape would touch an obstacle

    def _escape_command(self, index):
        kind, lin, sign = self.ESCAPES[index % len(self.ESCAPES)]
        lin = -abs(self.params.escape_vel) if lin is None else lin
        ang = sign * math.copysign(min(1.0, self.params.max_rotational_vel), self.stall_turn or 1.0)
        return kind, lin, ang

    def _escape_horizon(self):
        """An escape is slow and checked again every cycle: its roll-out covers the next two control
        cycles (the time a command may stay in force when one cycle is late), not the pursuit's
        collision_horizon, which at 0.1-0.15 m/s would refuse every move of a robot wedged within a
        few centimetres of a door's cells."""
        return min(self.params.collision_horizon, 2.0 / self.params.controller_frequency)

    @staticmethod
    def _moved(ref, pose):
        """Whether pose is more than 2 cm or 0.05 rad from ref."""
        return math.hypot(pose[0] - ref[0], pose[1] - ref[1]) > 0.02 or abs(_wrap(pose[2] - ref[2])) > 0.05

    def _watch_motion(self, now, pose, v, w):
        """Notices a stall: commands that move the robot, but for stall_time its pose did not change
        (the body touches something the footprint check on the costmap did not catch, e.g. a robot
        model larger than its configured footprint)."""
        moved = self.stall_ref is None or self._moved(self.stall_ref, pose)
        if moved or (v == 0.0 and w == 0.0) or self.escape_until is not None:
            self.stall_ref, self.stall_since, self.stall_turn = pose, now, w
            return
        if now - self.stall_since < self.params.stall_time:
            return
        kind, lin, ang = self._escape_command(self.escapes)
        self.escapes += 1
        self.escape_cmd = (kind, lin, ang)
        self.escape_until = now + self.params.stall_time
        LOG.info("stalled at (%.2f, %.2f) for %.1f s with %s; escape %d: %s for %.1f s", pose[0], pose[1],
                 now - self.stall_since, self.last_command, self.escapes, kind, self.params.stall_time)

    def _escape(self, now, pose):
        """The escape command while one runs; None when not escaping; NO_ESCAPE when this escape and
        every other one would touch an obstacle. A blocked escape gives way to the next one that is
        free; with none free computeVelocityCommands fails (not a (0, 0) command, which would count as
        valid control and keep a robot wedged in a doorway waiting without end), so that move_base's
        state machine replans and, after controller_patience, runs its recoveries."""
        if self.escape_until is None:
            return None
        if now >= self.escape_until:
            self.escape_until = None
            self.stall_ref = None
            return None
        horizon = self._escape_horizon()
        kind, lin, ang = self.escape_cmd
        if self._collides(pose, lin, ang, horizon):
            for k in range(1, len(self.ESCAPES)):
                candidate = self._escape_command(self.escapes - 1 + k)
                if candidate[0] != kind and not self._collides(pose, candidate[1], candidate[2], horizon):
                    kind, lin, ang = self.escape_cmd = candidate
                    break
            else:
                self.escape_until = None
                self.stall_ref = None
                if self.wedged_at is None:
                    self.wedged_at = pose
                self.last_command = ("no command: a stall at (%.2f, %.2f), and turning the other way, creeping "
                                     "forward and reversing would all touch an obstacle" % (pose[0], pose[1]))
                return self.NO_ESCAPE
        self.last_command = "escape: %s (%.2f m/s, %.2f rad/s)" % (kind, lin, ang)
        return lin, ang

    def _follow(self, pose):
        """Pure pursuit towards the path point lookahead metres ahead; turn in place when far off;
        None when every command would touch an obstacle.

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
        # base_local_planner turns in place no slower than min_in_place_vel_theta: a slower turn (the
        # pursuit's 2·err when the robot already faces its target) does not move the robot, and the
        # stall it causes is all that would be left.
        turn = math.copysign(max(abs(w), min(wmax, self.params.min_in_place_rotational_vel)), w if w else 1.0)
        candidates += [("turn in place", 0.0, turn), ("escape", -abs(self.params.escape_vel), 0.0)]
        for kind, cand_v, cand_w in candidates:
            # A turn in place is not held back by the outline check: it cannot take the centre
            # closer to anything, and a configured footprint larger than the body (the tutorials'
            # 0.46 m nose on Stage's PR2) would otherwise freeze the robot in every tight junction.
            # If the body does touch, the stall escape takes over.
            if cand_v == 0.0 or not self._collides(pose, cand_v, cand_w):
                self.last_command = "%s (%.2f m/s, %.2f rad/s)" % (kind, cand_v, cand_w)
                return cand_v, cand_w
        self.last_command = "no command: following (%.2f, %.2f), turning and reversing would all touch an obstacle" % (v, w)
        return None

    def _collides(self, pose, v, w, horizon=None):
        """Whether the footprint, driven at (v, w) for ``horizon`` seconds (collision_horizon by
        default), meets a lethal cell."""
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
        dt = (self.params.collision_horizon if horizon is None else horizon) / 4.0
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
