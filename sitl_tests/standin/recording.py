"""Recording: everything the autopilot received and did, for assertions."""
from __future__ import annotations

import json
import math
import threading
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List


@dataclass
class Event:
    wall: float      # seconds since stand-in start (wall clock)
    sim: float       # simulated seconds since start
    kind: str        # received | command | mode | arm | disarm | mission_upload | mission_clear | param | statustext | ...
    data: Dict[str, Any] = field(default_factory=dict)


class Recorder:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.events: List[Event] = []

    def add(self, wall: float, sim: float, kind: str, **data: Any) -> None:
        with self._lock:
            self.events.append(Event(wall, sim, kind, data))

    def of(self, kind: str) -> List[Event]:
        with self._lock:
            return [e for e in self.events if e.kind == kind]

    def snapshot(self) -> List[Event]:
        with self._lock:
            return list(self.events)

    def to_json(self) -> str:
        return json.dumps([asdict(e) for e in self.snapshot()], default=str)


def jsonable(x: Any) -> Any:
    if isinstance(x, float) and (math.isnan(x) or math.isinf(x)):
        return str(x)
    if isinstance(x, (bytes, bytearray)):
        return x.decode(errors="replace")
    if isinstance(x, (list, tuple)):
        return [jsonable(i) for i in x]
    return x
