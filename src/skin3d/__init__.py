# SPDX-License-Identifier: BSD-3-Clause
"""skin3d's Python tools: results analysis, plots, reports and checks (the programs are in scripts/).

Modules: tum (TUM trajectories), rotations (SO(3) helpers), stats (chi^2 and normal quantiles), plots (the
thesis' figures), report (the HTML page), slam_report, induration_table, nees (pose consistency),
gyro_bias (the gyroscope's bias from a still recording). The generated messages are skin3d.msg / skin3d.srv.
"""
