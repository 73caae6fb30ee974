#!/usr/bin/env python3
"""Launcher for the stand-in autopilot, which lives in the `standin` package next to this file.

Keeps ``python sitl_tests/standin_autopilot.py ...`` and ``import standin_autopilot`` working;
``python -m standin`` (from sitl_tests/) is the same program.
"""
import sys

from standin import *  # noqa: F401,F403
from standin import main

if __name__ == "__main__":
    sys.exit(main())
