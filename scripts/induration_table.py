#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""True vs measured plaque heights (the thesis' Table 4.2) (the code: skin3d.induration_table; --help for the usage)."""
import sys

from skin3d.induration_table import main

if __name__ == "__main__":
    sys.exit(main())
