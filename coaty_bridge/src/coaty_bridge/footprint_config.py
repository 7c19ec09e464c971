"""The bridge node's footprint parameters (coaty_bridge README, "Fleet robot footprints"), validated, and the
advert schedule they make."""
import rospy

from coaty_bridge.footprint import PARKED_VALIDITY, AdvertSchedule, MAX_VALID_FOR


class FootprintConfig:
    """The node's footprint parameters (fleet robots are never shared); ValueError names a bad one."""

    def __init__(self, topic="move_base/global_costmap/footprint", rate=2.0, robot_timeout=3.0, advertise=True,
                 min_move=0.1, parked_interval=30.0, near_distance=5.0, far_move=1.0,
                 driving_interval=2.0):
        if not isinstance(topic, str) or not topic:
            raise ValueError("parameter footprint_topic = %r: must be a topic name" % (topic,))
        for name, value, low, high in (("footprint_rate", rate, 0.1, 50.0), ("robot_timeout", robot_timeout, 0.1, 3600.0),
                                       ("footprint_min_move", min_move, 0.0, 10.0),
                                       ("footprint_parked_interval", parked_interval, 0.0,
                                        MAX_VALID_FOR / PARKED_VALIDITY),
                                       ("footprint_near_distance", near_distance, 0.0, 100.0),
                                       ("footprint_far_move", far_move, 0.0, 10.0),
                                       ("footprint_driving_interval", driving_interval, 0.0,
                                        MAX_VALID_FOR / PARKED_VALIDITY)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
                raise ValueError("parameter %s = %r: must be %g..%g" % (name, value, low, high))
        if not isinstance(advertise, bool):
            raise ValueError("parameter advertise_footprint = %r: must be true or false" % (advertise,))
        if robot_timeout * rate < 2.0:
            raise ValueError("parameter robot_timeout = %r: shorter than two adverts at footprint_rate %r Hz; a "
                             "robot would be forgotten between adverts" % (robot_timeout, rate))
        self.topic, self.rate, self.robot_timeout, self.advertise = topic, float(rate), float(robot_timeout), advertise
        if near_distance > 0 and not min_move <= far_move:
            raise ValueError("parameter footprint_far_move = %r: must be at least footprint_min_move %r (or "
                             "footprint_near_distance 0)" % (far_move, min_move))
        self.min_move = float(min_move)
        self.parked_interval = float(parked_interval)
        self.near_distance, self.far_move = float(near_distance), float(far_move)
        self.driving_interval = float(driving_interval)

    def schedule(self, area_size=0.0):
        """The advert schedule; ``area_size`` is the bridge's footprint_area_size (a new square sends at once)."""
        return AdvertSchedule(self.rate, self.min_move, self.parked_interval,
                              far_move=self.far_move if self.near_distance > 0 else 0.0,
                              driving_interval=self.driving_interval, area_size=area_size)

    @classmethod
    def from_params(cls):
        return cls(topic=rospy.get_param("~footprint_topic", "move_base/global_costmap/footprint"),
                   rate=rospy.get_param("~footprint_rate", 2.0),
                   robot_timeout=rospy.get_param("~robot_timeout", 3.0),
                   advertise=rospy.get_param("~advertise_footprint", True),
                   min_move=rospy.get_param("~footprint_min_move", 0.1),
                   parked_interval=rospy.get_param("~footprint_parked_interval", 30.0),
                   near_distance=rospy.get_param("~footprint_near_distance", 5.0),
                   far_move=rospy.get_param("~footprint_far_move", 1.0),
                   driving_interval=rospy.get_param("~footprint_driving_interval", 2.0))
