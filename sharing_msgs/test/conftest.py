"""sharing_msgs' pure helpers are importable from src/ without a built workspace (appended, so a
sourced workspace's sharing_msgs, which also has the generated msg package, wins)."""
import os
import sys

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "src")
if SRC not in sys.path:
    sys.path.append(SRC)
