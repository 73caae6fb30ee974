"""The companion binary starts and answers --help: the floor every other SITL test stands on."""
import os
import subprocess


def test_companion_binary_runs():
    exe = os.environ["COMPANION_BIN"]
    out = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "simulate" in out.stdout
