#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Table 7.2 of the thesis next to skin3d's SLAM experiments, and their plots (the code: skin3d.slam_report; --help for the usage)."""
import sys

from skin3d.slam_report import main

if __name__ == "__main__":
    sys.exit(main())
