from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(
    packages=["sharing_handler_py"],
    package_dir={"": "src"},
))
