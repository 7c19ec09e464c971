"""The rules of authority (DESIGN.md §6a, §6c): what this receiver lets one peer do, whatever its
message says. Pure Python (no rospy, no paho); the sharing handler, the Coaty bridge and the VDA 5050
bridge all use these, so no two of them can disagree on a rule.

- ``policy``: the caps of one obstacle and one message (extent, cells, lifetime, version), the stamp
  window (``PeerPolicy``) and the cells of a message inside its rectangle (``check_cells_inside``);
- ``evidence``: plausible evidence, the cells a peer's sensors could have seen from a pose it advertised
  (``PoseHistory``, ``Sighting``, ``EvidenceRule``);
- ``quotas``: what one source may cost a receiver (``TokenBuckets``, ``SourceQuotas``, ``DropReport``);
- ``fairness``: one queue per source, served round-robin (``FairQueue``);
- ``errors``: ``AuthorityError``, raised by every check, with the drop counter's name.
"""
from sharing_msgs.authority.errors import AuthorityError  # noqa: F401
from sharing_msgs.authority.fairness import FairQueue  # noqa: F401
from sharing_msgs.authority.evidence import EvidenceRule, Judgement, PoseHistory, Sighting  # noqa: F401
from sharing_msgs.authority.policy import (MASTER_CONTROL, MIN_VERSION_STEP, OPERATOR_VERSION_MARGIN,  # noqa: F401
                                           PeerPolicy, check_cells_inside, rectangle_capacity, single_robot_extent)
from sharing_msgs.authority.quotas import DropReport, SourceQuotas, TokenBuckets  # noqa: F401
