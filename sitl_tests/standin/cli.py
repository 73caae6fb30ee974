"""The command line: ``python -m standin`` (from sitl_tests/)."""
from __future__ import annotations

import argparse
import json
import time
from typing import List, Optional

from .autopilot import StandinAutopilot
from .config import StandinConfig


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description="Stand-in ArduPilot Copter (test fixture; loopback only)")
    ap.add_argument("--listen", default="tcp:127.0.0.1:5760", help="tcp:HOST:PORT | udp:HOST:PORT | udpout:HOST:PORT")
    ap.add_argument("--sysid", type=int, default=1)
    ap.add_argument("--speedup", type=float, default=1.0, help="simulated seconds per wall second (like SIM_SPEEDUP)")
    ap.add_argument("--ekf-ready-s", type=float, default=30.0, help="simulated seconds until the position estimate is ready")
    ap.add_argument("--disarm-delay-s", type=float, default=10.0)
    ap.add_argument("--signing-key", help="hex of a 32-byte MAVLink 2 signing key")
    ap.add_argument("--mission-request-int", action="store_true", help="request upload items with MISSION_REQUEST_INT")
    ap.add_argument("--garbage-period", type=float, default=0.0, help="inject garbage and malformed frames every N wall s")
    ap.add_argument("--record", help="write the recording (JSON) here on exit")
    ap.add_argument("--duration", type=float, default=0.0, help="exit after N wall seconds (0 = until Ctrl-C)")
    a = ap.parse_args(argv)
    cfg = StandinConfig(listen=a.listen, sysid=a.sysid, speedup=a.speedup, ekf_ready_s=a.ekf_ready_s,
                        disarm_delay_s=a.disarm_delay_s, mission_request_int=a.mission_request_int,
                        signing_key=bytes.fromhex(a.signing_key) if a.signing_key else None,
                        garbage_period_wall=a.garbage_period)
    ap_ = StandinAutopilot(cfg).start()
    print(f"stand-in ArduCopter listening on {ap_.url} (speedup {cfg.speedup})", flush=True)
    try:
        t0 = time.monotonic()
        while a.duration <= 0 or time.monotonic() - t0 < a.duration:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        ap_.stop()
        if a.record:
            with open(a.record, "w") as f:
                f.write(ap_.rec.to_json())
        print(json.dumps(ap_.counters), flush=True)
    return 0
