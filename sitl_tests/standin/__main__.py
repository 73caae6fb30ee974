"""``python -m standin`` (from sitl_tests/): run the stand-in autopilot."""
import sys

from .cli import main

sys.exit(main())
