# SPDX-License-Identifier: BSD-3-Clause
# The Python package skin3d (src/skin3d/) for catkin_python_setup(): catkin installs it and makes it importable
# from the devel space; never run this file by hand (http://docs.ros.org/api/catkin/html/user_guide/setup_dot_py.html).
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=["skin3d"], package_dir={"": "src"}))
