from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

# The hand-written helpers under src/sharing_msgs sit beside the generated msg/srv modules:
# catkin's devel __init__.py extends the package path to both.
setup(**generate_distutils_setup(packages=["sharing_msgs", "sharing_msgs.authority"], package_dir={"": "src"}))
