"""A stand-in ArduPilot Copter: a TEST FIXTURE, not an autopilot.

It speaks MAVLink 2 over loopback TCP/UDP and behaves, for everything a companion computer uses, the
way ArduCopter does, so the `companion fly` shell can be tested without building ArduPilot. Where a
behaviour is an ArduPilot quirk, the comment names the ArduPilot source file it comes from (paths in
the ArduPilot/ardupilot repository). Where the stand-in simplifies, the comment says "stand-in".
docs/sitl.md describes it; `SITL_URL` points the tests at a real SITL instead.

Use it three ways:
  * imported: ``StandinAutopilot(StandinConfig(...)).start()`` (what sitl_tests/conftest.py does),
  * as a module from sitl_tests/: ``python -m standin --listen udp:127.0.0.1:14550``,
  * as a script: ``python sitl_tests/standin_autopilot.py --listen tcp:127.0.0.1:5760`` (a launcher for this package).

Time: vehicle dynamics and vehicle timers (EKF convergence, DISARM_DELAY, battery drain, GPS-loss
failsafe) run on *simulated* time = wall time x ``speedup`` (like SITL's SIM_SPEEDUP). Link timing
(stream intervals, mission protocol re-requests and timeouts, link outages) stays on wall time,
because the companion's own link timers are wall-clock.

The modules follow what the autopilot does:
  * ``vocabulary``: ArduCopter's modes, parameters, stream defaults and mission limits,
  * ``config``: what a test may change (StandinConfig),
  * ``recording``: the events a test asserts on,
  * ``link``: sockets, framing, signing, the receive path and routing,
  * ``handlers``: MAVLink message and command handlers, message intervals, parameters,
  * ``mission``: the mission protocol and flying the mission in AUTO,
  * ``vehicle``: the vehicle's state, arming and mode changes,
  * ``physics``: vehicle motion, battery, obstacle sensor, geometry,
  * ``telemetry``: the messages sent and their schedule,
  * ``autopilot``: StandinAutopilot itself (lifecycle, clocks, test controls, main loop),
  * ``monitors``: the onboard camera/tracking application (OnboardMonitors),
  * ``cli``: the command line.
"""
from .autopilot import StandinAutopilot
from .cli import main
from .config import StandinConfig
from .link import Link
from .monitors import MONITOR_NAMES, OnboardMonitors
from .recording import Event, Recorder
from .vehicle import Vehicle
from .vocabulary import (DEFAULT_INTERVALS_MS, DEFAULT_PARAMS, EARTH_R, HOME_ALT_AMSL, HOME_LAT, HOME_LON, MODE_NAMES,
                         MODES, mavlink)

__all__ = [
    "DEFAULT_INTERVALS_MS", "DEFAULT_PARAMS", "EARTH_R", "Event", "HOME_ALT_AMSL", "HOME_LAT", "HOME_LON", "Link",
    "MODE_NAMES", "MODES", "MONITOR_NAMES", "OnboardMonitors", "Recorder", "StandinAutopilot", "StandinConfig",
    "Vehicle", "main", "mavlink",
]
