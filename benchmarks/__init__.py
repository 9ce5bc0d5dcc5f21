# SPDX-License-Identifier: GPL-3.0-or-later
"""Benchmarks: run time against error, side by side with Blender, and the stress suite.

    python -m benchmarks --quick     # every section at small sizes, under five minutes
    python -m benchmarks --full      # the issue sizes
    python -m benchmarks --gpu-only  # frames per second at 1920x1080 on a GPU machine

writes benchmarks/REPORT.md and its PNG plots beside it.
"""
