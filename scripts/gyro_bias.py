#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""The gyroscope's bias from a recording of the rig standing still (the code: skin3d.gyro_bias; --help for the usage)."""
import sys

from skin3d.gyro_bias import main

if __name__ == "__main__":
    sys.exit(main())
