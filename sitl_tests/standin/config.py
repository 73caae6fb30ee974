"""What a test may change about the stand-in."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

from .vocabulary import HOME_ALT_AMSL, HOME_LAT, HOME_LON


@dataclass
class StandinConfig:
    """Everything a test may want to change. Times are in simulated seconds unless named *_wall."""

    listen: str = "tcp:127.0.0.1:0"     # tcp:HOST:PORT (server), udp:HOST:PORT (bind, reply to last sender), udpout:HOST:PORT
    sysid: int = 1
    compid: int = 1                     # MAV_COMP_ID_AUTOPILOT1
    speedup: float = 1.0
    ekf_ready_s: float = 30.0           # SITL typically needs tens of seconds before "Need Position Estimate" clears
    disarm_delay_s: float = 10.0        # DISARM_DELAY
    gps_loss_ekf_s: float = 3.0         # stand-in: dead-reckoning time before POS_HORIZ_ABS drops after GPS loss
    home: Tuple[float, float, float] = (HOME_LAT, HOME_LON, HOME_ALT_AMSL)
    signing_key: Optional[bytes] = None  # 32 bytes; sign everything sent, reject unsigned received
    mission_request_int: bool = False   # False: request items with legacy MISSION_REQUEST as MissionItemProtocol::queued_request_send does
    physics_hz: float = 50.0
    garbage_period_wall: float = 0.0    # >0: inject a burst of garbage + malformed frames this often (wall s)
    capture_wire: bool = False          # keep every byte sent and received per link (Link.wire_out / wire_in)
    seed: int = 1

    def __post_init__(self) -> None:
        if self.speedup <= 0:
            raise ValueError("speedup must be > 0")
