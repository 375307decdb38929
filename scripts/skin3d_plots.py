#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""The thesis' plots from skin3d results directories (the code: skin3d.plots; --help for the usage)."""
import sys

from skin3d.plots import main

if __name__ == "__main__":
    sys.exit(main())
