"""scripts/sitl_ardupilot.sh fails fast, with a message naming what to set, when no ArduPilot is given."""
import os
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "sitl_ardupilot.sh"
pytestmark = pytest.mark.standin_only   # checks the script's own refusal, not a SITL


def run(env_extra):
    env = {k: v for k, v in os.environ.items() if k not in ("ARDUPILOT_DIR", "ARDUCOPTER_BIN", "SITL_DEFAULTS")}
    env.update(env_extra)
    return subprocess.run(["bash", str(SCRIPT)], capture_output=True, text=True, env=env, timeout=30)


def test_without_ardupilot_it_says_what_to_set(tmp_path):
    out = run({})
    assert out.returncode == 2
    assert "ARDUPILOT_DIR" in out.stderr and "ARDUCOPTER_BIN" in out.stderr
    assert "== arducopter" not in out.stdout          # nothing was started


def test_a_missing_binary_or_tree_is_named(tmp_path):
    out = run({"ARDUCOPTER_BIN": str(tmp_path / "arducopter")})
    assert out.returncode == 2 and str(tmp_path / "arducopter") in out.stderr
    out = run({"ARDUPILOT_DIR": str(tmp_path / "nope")})
    assert out.returncode == 2 and "is not a directory" in out.stderr
    # a tree without a SITL build
    out = run({"ARDUPILOT_DIR": str(tmp_path)})
    assert out.returncode == 2 and "build/sitl/bin/arducopter" in out.stderr
    # a binary but no defaults file
    fake = tmp_path / "arducopter"
    fake.write_text("#!/bin/sh\nexit 1\n")
    fake.chmod(0o755)
    out = run({"ARDUCOPTER_BIN": str(fake)})
    assert out.returncode == 2 and "SITL_DEFAULTS" in out.stderr
