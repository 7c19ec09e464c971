"""Offline bag replay: the sharing layer's C++ core and the pure SharingHandler over recorded bags.

No roscore: bags are read with Debian's rosbag Python API, transforms are looked up in a small
transform chain of this package (tf_chain.py), and every robot of the bag gets its own
SharingCore + SharingHandler, fed in the bag's timestamp order. Entry point:
``rosrun sharing_replay replay`` (cli.py). See README.md.
"""
