#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""Pose consistency (NEES) of SLAM runs against their ground truth (the code: skin3d.nees; --help for the usage)."""
import sys

from skin3d.nees import main

if __name__ == "__main__":
    sys.exit(main())
