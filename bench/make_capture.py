"""Write a realistic MAVLink telemetry capture for the ingest benchmark (bench/compare).

What a companion computer hears on its autopilot link, about 50 frames/s:
- the autopilot (sys 1, comp 1): the streams params/link.toml requests, at those rates (SYS_STATUS,
  BATTERY_STATUS, GLOBAL_POSITION_INT, GPS_RAW_INT, VIBRATION, WIND, EKF_STATUS_REPORT,
  MISSION_CURRENT, EXTENDED_SYS_STATE, DISTANCE_SENSOR, OBSTACLE_DISTANCE, HOME_POSITION,
  SYSTEM_TIME), its 1 Hz HEARTBEAT, ATTITUDE 10 Hz and VFR_HUD 2 Hz (ArduPilot's default GCS
  streams), and a STATUSTEXT now and then (event-driven, every 5 s here);
- an onboard monitor (sys 1, comp 100, camera): HEARTBEAT 1 Hz, CAMERA_TRACKING_IMAGE_STATUS
  2 Hz, NAMED_VALUE_FLOAT tgt_det/trk_conf/lum/cpu_load/free_tiles at 1 Hz each;
- a SiK telemetry radio (sys 51, comp 68): RADIO_STATUS 1 Hz in MAVLink 1, as SiK firmware sends it;
- the autopilot's first 10 s in MAVLink 1 (ArduPilot answers in v1 until it hears v2);
- a little garbage: every ~300 frames 1-40 bytes of line noise (without the 0xFD/0xFE frame
  markers: with them, a bogus length can swallow the next real frame in pymavlink, which skips a
  whole bad frame, while the companion's reader rescans from the next byte: a real difference,
  but one that would make "same messages" a test of resync policy rather than of decoding), and
  every ~500 frames one payload byte flipped (CRC fails: both parsers drop that frame).

Also writes the chunk sizes the stream is fed in (64..1024 bytes, as UDP datagrams or serial
reads give), one per line, so both sides see the same chunk boundaries.
Seeded: the same arguments give the same bytes. Usage:
  python bench/make_capture.py OUT.bin OUT.chunks [seconds=300] [seed=8]
"""

import math
import os
import random
import sys

os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v10 import ardupilotmega as v1  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as v2  # noqa: E402

# Message -> rate (Hz). The first block mirrors params/link.toml [streams].
AUTOPILOT_RATES = {
    "SYS_STATUS": 2.0, "BATTERY_STATUS": 1.0, "GLOBAL_POSITION_INT": 5.0, "GPS_RAW_INT": 2.0,
    "VIBRATION": 2.0, "WIND": 1.0, "EKF_STATUS_REPORT": 2.0, "MISSION_CURRENT": 1.0,
    "EXTENDED_SYS_STATE": 1.0, "DISTANCE_SENSOR": 5.0, "OBSTACLE_DISTANCE": 5.0,
    "HOME_POSITION": 0.2, "SYSTEM_TIME": 1.0,
    "HEARTBEAT": 1.0, "ATTITUDE": 10.0, "VFR_HUD": 2.0, "STATUSTEXT": 0.2,
}
MONITOR_RATES = {"HEARTBEAT": 1.0, "CAMERA_TRACKING_IMAGE_STATUS": 2.0, "NAMED_VALUE_FLOAT": 5.0}
RADIO_RATES = {"RADIO_STATUS": 1.0}
V1_SECONDS = 10.0
HOME = (473977420, 85455940, 488.0)  # lat e7, lon e7, amsl m (ArduPilot SITL's default home)
MONITOR_NAMES = [b"tgt_det", b"trk_conf", b"lum", b"cpu_load", b"free_tiles"]
TEXTS = [b"EKF3 IMU0 is using GPS", b"Mission: 3 WP", b"Reached command #2", b"PreArm: Hardware safety switch",
         b"Vibration compensation ON", b"Throttle armed", b"GPS 1: detected as u-blox"]


class World:
    """A drone flying a slow circle with noisy sensors: plausible, varying field values."""

    def __init__(self, rng):
        self.r = rng
        self.battery = 100.0

    def at(self, t):
        r = self.r
        ang = t / 60.0
        self.t = t
        self.lat = HOME[0] + int(2000 * math.sin(ang))
        self.lon = HOME[1] + int(3000 * (1 - math.cos(ang)))
        self.alt = 20.0 + 0.5 * math.sin(t / 7.0)
        self.vx, self.vy = int(500 * math.cos(ang)), int(500 * math.sin(ang))
        self.hdg = (math.degrees(ang) + 90) % 360
        self.battery = max(0.0, 100.0 - t / 40.0)
        self.obstacle = 12.0 + 10 * math.sin(t / 13.0) + r.gauss(0, 0.3)
        return self


def frames(seconds, rng):
    """(time, source, version, message) in send order."""
    w = World(rng)
    sched = []
    for src, rates in (("ap", AUTOPILOT_RATES), ("mon", MONITOR_RATES), ("radio", RADIO_RATES)):
        for name, hz in rates.items():
            period = 1.0 / hz
            k = 0
            phase = rng.random() * period
            while phase + k * period < seconds:
                sched.append((phase + k * period, src, name, k))
                k += 1
    sched.sort()
    for t, src, name, k in sched:
        w.at(t)
        version = 1 if src == "radio" or (src == "ap" and t < V1_SECONDS) else 2
        if version == 1 and name == "OBSTACLE_DISTANCE":
            continue  # id 330 has no MAVLink 1 encoding
        yield t, src, version, name, k, w


def build(mav, name, k, w, rng):
    t = w.t
    boot_ms = int(t * 1000) + 5000
    g = rng.gauss
    if name == "HEARTBEAT":
        if mav.srcComponent == 1:
            return mav.heartbeat_encode(v2.MAV_TYPE_QUADROTOR, v2.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                        v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | v2.MAV_MODE_FLAG_SAFETY_ARMED
                                        | v2.MAV_MODE_FLAG_STABILIZE_ENABLED, 3 if t > 30 else 4,
                                        v2.MAV_STATE_ACTIVE, 3)
        return mav.heartbeat_encode(v2.MAV_TYPE_CAMERA, v2.MAV_AUTOPILOT_INVALID, 0, 0, v2.MAV_STATE_ACTIVE, 3)
    if name == "SYS_STATUS":
        s = 0x3020FC2F
        return mav.sys_status_encode(s, s, s, 250 + int(g(0, 20)), int(15800 - 10 * t / 60), 1250 + int(g(0, 50)),
                                     int(w.battery), 0, 0, 0, 0, 0, 0)
    if name == "BATTERY_STATUS":
        return mav.battery_status_encode(0, v2.MAV_BATTERY_FUNCTION_ALL, v2.MAV_BATTERY_TYPE_LIPO, 3200,
                                         [3950, 3948, 3951, 3949] + [65535] * 6, 1250, int(t * 1.4),
                                         int(t * 6.5), int(w.battery))
    if name == "GLOBAL_POSITION_INT":
        return mav.global_position_int_encode(boot_ms, w.lat, w.lon, int((HOME[2] + w.alt) * 1000),
                                              int(w.alt * 1000), w.vx, w.vy, int(g(0, 10)), int(w.hdg * 100))
    if name == "GPS_RAW_INT":
        return mav.gps_raw_int_encode(int(t * 1e6) + 5_000_000, 3, w.lat + int(g(0, 20)), w.lon + int(g(0, 20)),
                                      int((HOME[2] + w.alt) * 1000), 121, 200, 500, int(w.hdg * 100) % 36000,
                                      14 + int(g(0, 1)) % 3)
    if name == "VIBRATION":
        return mav.vibration_encode(int(t * 1e6), abs(g(3, 1)), abs(g(3, 1)), abs(g(4, 1)), 0, 0, k // 100)
    if name == "WIND":
        return mav.wind_encode((200 + g(0, 5)) % 360, abs(g(2, 0.5)), g(0, 0.1))
    if name == "EKF_STATUS_REPORT":
        return mav.ekf_status_report_encode(0x3FF, abs(g(0.05, 0.01)), abs(g(0.04, 0.01)), abs(g(0.03, 0.01)),
                                            abs(g(0.02, 0.01)), 0.0)
    if name == "MISSION_CURRENT":
        return mav.mission_current_encode(1 + int(t // 60) % 6)
    if name == "EXTENDED_SYS_STATE":
        return mav.extended_sys_state_encode(v2.MAV_VTOL_STATE_UNDEFINED,
                                             v2.MAV_LANDED_STATE_IN_AIR if t > 15 else v2.MAV_LANDED_STATE_ON_GROUND)
    if name == "DISTANCE_SENSOR":
        return mav.distance_sensor_encode(boot_ms, 20, 4000, int(max(0.2, w.obstacle) * 100),
                                          v2.MAV_DISTANCE_SENSOR_LASER, 0, v2.MAV_SENSOR_ROTATION_NONE, 0)
    if name == "OBSTACLE_DISTANCE":
        d = [min(4001, max(20, int((w.obstacle + 3 * abs(i - 36) / 10 + g(0, 0.2)) * 100))) for i in range(72)]
        return mav.obstacle_distance_encode(int(t * 1e6), v2.MAV_DISTANCE_SENSOR_LASER, d, 5, 20, 4000)
    if name == "HOME_POSITION":
        return mav.home_position_encode(HOME[0], HOME[1], int(HOME[2] * 1000), 0.0, 0.0, 0.0,
                                        [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)
    if name == "SYSTEM_TIME":
        return mav.system_time_encode(1_700_000_000_000_000 + int(t * 1e6), boot_ms)
    if name == "ATTITUDE":
        return mav.attitude_encode(boot_ms, g(0, 0.05), g(0, 0.05), math.radians(w.hdg) - math.pi,
                                   g(0, 0.01), g(0, 0.01), g(0, 0.01))
    if name == "VFR_HUD":
        return mav.vfr_hud_encode(5.0 + g(0, 0.3), 5.0 + g(0, 0.2), int(w.hdg), 45, HOME[2] + w.alt, g(0, 0.1))
    if name == "STATUSTEXT":
        return mav.statustext_encode(v2.MAV_SEVERITY_INFO, TEXTS[k % len(TEXTS)])
    if name == "CAMERA_TRACKING_IMAGE_STATUS":
        active = (t // 20) % 2 == 1
        return mav.camera_tracking_image_status_encode(
            v2.CAMERA_TRACKING_STATUS_FLAGS_ACTIVE if active else v2.CAMERA_TRACKING_STATUS_FLAGS_IDLE,
            v2.CAMERA_TRACKING_MODE_POINT, v2.CAMERA_TRACKING_TARGET_DATA_IN_STATUS,
            0.5 + g(0, 0.05) if active else float("nan"), 0.5 + g(0, 0.05) if active else float("nan"),
            0.1, 0.4, 0.4, 0.6, 0.6)
    if name == "NAMED_VALUE_FLOAT":
        n = MONITOR_NAMES[k % len(MONITOR_NAMES)]
        val = {b"tgt_det": float((t // 20) % 2), b"trk_conf": 0.8 + g(0, 0.05), b"lum": 800 + g(0, 20),
               b"cpu_load": 0.4 + g(0, 0.05), b"free_tiles": 2.0}[n]
        return mav.named_value_float_encode(boot_ms, n, val)
    if name == "RADIO_STATUS":
        return mav.radio_status_encode(180 + int(g(0, 5)) % 20, 175, 95, 40, 42, k // 50, k // 200)
    raise ValueError(name)


def main():
    out, chunks_out = sys.argv[1], sys.argv[2]
    seconds = float(sys.argv[3]) if len(sys.argv) > 3 else 300.0
    seed = int(sys.argv[4]) if len(sys.argv) > 4 else 8
    rng = random.Random(seed)
    srcs = {("ap", 1): v1.MAVLink(None, 1, 1), ("ap", 2): v2.MAVLink(None, 1, 1),
            ("mon", 2): v2.MAVLink(None, 1, 100), ("radio", 1): v1.MAVLink(None, 51, 68)}
    buf = bytearray()
    n = 0
    for _t, src, version, name, k, w in frames(seconds, rng):
        mav = srcs[(src, version)]
        # the v2 and v1 encoders of the autopilot share one sequence counter, as on a real link
        if src == "ap":
            other = srcs[("ap", 3 - version)]
            mav.seq = other.seq = max(mav.seq, other.seq)
        frame = bytearray(build(mav, name, k, w, rng).pack(mav))
        n += 1
        if n % 500 == 0:
            hdr = 10 if frame[0] == 0xFD else 6
            i = hdr + rng.randrange(max(1, len(frame) - hdr - 2))
            frame[i] ^= 1 << rng.randrange(8)
        if n % 300 == 0:
            buf += bytes(rng.choice([b for b in range(256) if b not in (0xFD, 0xFE)])
                         for _ in range(rng.randint(1, 40)))
        buf += frame
    with open(out, "wb") as f:
        f.write(buf)
    sizes = []
    left = len(buf)
    while left > 0:
        s = min(left, rng.randint(64, 1024))
        sizes.append(s)
        left -= s
    with open(chunks_out, "w") as f:
        f.write("\n".join(map(str, sizes)) + "\n")
    print(f"wrote {out}: {len(buf)} bytes, {n} frames over {seconds:g} s, {len(sizes)} chunks", file=sys.stderr)


if __name__ == "__main__":
    main()
