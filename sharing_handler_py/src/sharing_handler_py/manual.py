"""Obstacles added and removed by hand (DESIGN.md §5.11, issue 28): the handler's services. A mixin of
the SharingHandler (logic.py): a manual obstacle is shared like a detected one, a removal goes out as
this robot's update clearing every present cell.
"""
import logging

from sharing_handler_py.entry import rectangles_meet, remaining_deadline
from sharing_handler_py.errors import REFUSED, InvalidMessageError, InvalidRequestError
from sharing_handler_py.validation import Obstacle, Rectangle, check_indexes, check_message_values
from sharing_msgs import obstacle_rules

_log = logging.getLogger("sharing_handler_py.logic")


class ManualMixin:
    """add_manual and remove, for the node's add_obstacle and remove_obstacle services."""

    def add_manual(self, rectangle, marked=(), deadline=0, frame_id=""):
        """Adds an obstacle by hand and shares it like a detected one. `rectangle` is a Rectangle
        or [min_x, min_y, max_x, max_y]; without `marked`, every cell whose centre lies in the
        rectangle is marked; deadline 0 = obstacle_duration. Returns the authorised Obstacle;
        raises InvalidRequestError saying why not."""
        if self._geometry is None:
            raise InvalidRequestError("no map grid known yet: cannot turn a rectangle into cells")
        try:
            if not isinstance(rectangle, Rectangle):
                rectangle = Rectangle.from_sequence(rectangle)
            if isinstance(deadline, bool) or not isinstance(deadline, int) \
                    or not 0 <= deadline <= obstacle_rules.MAX_UINT32:
                raise InvalidRequestError("deadline %r is not 0..%d s" % (deadline, obstacle_rules.MAX_UINT32))
            obstacle = Obstacle(uuid="", marked=(), cleared=(), deadline=0, rectangle=rectangle,
                                source=self.robot_name, geometry=self._geometry, frame_id=frame_id,
                                stamp=self._clock())
            check_message_values(obstacle)  # the rectangle lies on the grid, the stamp is ROS time
            # An obstacle blocks a pathway; a huge rectangle would make every later proposal under it
            # redundant on every robot. Shared under this robot's name, it gets a robot's cap everywhere.
            self._policy.check_extent(rectangle, "rectangle", self.robot_name)
            marked = tuple(int(c) for c in marked) or self._geometry.cells_in(rectangle)
            if not marked:
                raise InvalidRequestError("rectangle %s covers no cell of the map (%s)"
                                          % (rectangle, self._geometry))
            obstacle = obstacle.replace(marked=marked)
            check_message_values(obstacle)
            check_indexes(obstacle, self._geometry, self._max_cells)
            self._policy.check_cells(len(marked), self._geometry, "rectangle %s" % rectangle, self.robot_name)
            self._check_inside(obstacle, "manual obstacle")
        except REFUSED as err:
            raise InvalidRequestError(str(err)) from err
        self._counters["manual"] += 1
        near = self._near(rectangle, len(marked))
        if near is None:
            return self._authorise(obstacle, int(deadline) or self._deadline)
        update = self._merge_proposal(obstacle, near)
        if update is None:
            # the update it would become was refused (and counted): say so, never return None
            raise InvalidRequestError("rectangle %s lies within merge_distance of obstacle %s, and the "
                                      "update of it was refused (see the log)" % (rectangle, near.uuid))
        return update

    def remove(self, uuid=None, rectangle=None, requested_by=""):
        """Removes obstacles fleet-wide by hand: `uuid`, or every listed obstacle whose rectangle meets
        `rectangle` (a Rectangle or [min_x, min_y, max_x, max_y]). Each goes out as this robot's update
        clearing every present cell (as if seen free), to the fleet and to the layer, so every robot drops
        it (issue 26's rule, issue 28's service). Returns the uuids removed; raises InvalidRequestError
        saying why nothing could be."""
        if not requested_by or not str(requested_by).strip():
            raise InvalidRequestError("say who asks (requested_by): a removal is logged with its requester")
        if uuid:
            uuid = self.resolve(uuid)
            entry = self._entries.get(uuid)
            if entry is None or not entry.present:
                raise InvalidRequestError("no obstacle %s is listed here" % uuid)
            targets = [entry]
        else:
            try:
                if not isinstance(rectangle, Rectangle):
                    rectangle = Rectangle.from_sequence(rectangle)
            except (InvalidMessageError, TypeError, ValueError) as err:
                raise InvalidRequestError("give a uuid or a rectangle [min_x, min_y, max_x, max_y]: %s" % err) \
                    from None
            targets = [e for _u, e in sorted(self._entries.items()) if e.present and rectangles_meet(e.rectangle, rectangle)]
            if not targets:
                raise InvalidRequestError("no listed obstacle meets %s" % (rectangle,))
        removed = []
        for entry in targets:
            clear = Obstacle(uuid=entry.uuid, marked=(), cleared=tuple(sorted(entry.present)),
                             deadline=remaining_deadline(entry.expires_at - self._clock()),
                             rectangle=entry.rectangle, source=self.robot_name, geometry=entry.geometry,
                             version=entry.max_version + 1, frame_id=entry.frame_id, stamp=self._clock())
            _log.info("%s: obstacle %s (from %s, %d cells) removed by hand, requested by %s", self.robot_name,
                      entry.uuid, entry.source, len(entry.present), str(requested_by)[:80])
            self._to_fleet(clear)
            self._counters["updates_out"] += 1
            self._to_layer(clear)
            entry.apply(clear)
            self._note_shown(entry, True, clear)  # (only listed obstacles are targets)
            removed.append(entry.uuid)
        self._on_change()
        return removed
