#!/usr/bin/python3
# SPDX-License-Identifier: BSD-3-Clause
"""One self-contained HTML page for one or more skin3d results directories (the code: skin3d.report; --help for the usage)."""
import sys

from skin3d.report import main

if __name__ == "__main__":
    sys.exit(main())
