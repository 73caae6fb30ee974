"""ArduCopter vocabulary: modes, parameters, stream defaults, mission protocol limits, as ArduPilot names them."""
from __future__ import annotations

import os
from typing import Dict

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

# Copter custom modes (ArduCopter/mode.h `enum class Number`; also the COPTER_MODE enum in
# ardupilotmega.xml). Only the ones a companion uses are simulated.
MODES = {
    "STABILIZE": 0,
    "ALT_HOLD": 2,
    "AUTO": 3,
    "GUIDED": 4,
    "LOITER": 5,
    "RTL": 6,
    "LAND": 9,
    "BRAKE": 17,
}
MODE_NAMES = {v: k for k, v in MODES.items()}
# Modes that need a position estimate (Mode::requires_GPS() is true for these in ArduCopter/mode_*.cpp).
POSITION_MODES = {MODES[m] for m in ("AUTO", "GUIDED", "LOITER", "RTL", "BRAKE")}
# Modes that refuse arming: ModeAuto::allows_arming() is false unless AUTO_OPTIONS allows it
# (ArduCopter/mode_auto.cpp); RTL and LAND return false too (ArduCopter/mode.h).
NOT_ARMABLE = {MODES["AUTO"], MODES["RTL"], MODES["LAND"]}
# Modes reported with MAV_MODE_FLAG_GUIDED_ENABLED (GCS_MAVLINK_Copter::base_mode(),
# ArduCopter/GCS_Mavlink.cpp).
GUIDED_FLAG_MODES = {MODES[m] for m in ("AUTO", "GUIDED", "LOITER", "RTL", "BRAKE")}

# AP_Arming.cpp: PREARM_DISPLAY_PERIOD 30 (s between repeats of a failing pre-arm check while disarmed).
PREARM_DISPLAY_PERIOD_S = 30.0

# Default home: SITL's CMAC location (Tools/autotest/locations.txt "CMAC").
HOME_LAT, HOME_LON, HOME_ALT_AMSL = -35.363261, 149.165230, 584.0
EARTH_R = 6378137.0

# EKF_STATUS_REPORT flags (EKF_STATUS_FLAGS in common.xml).
EKF_OK_FLAGS = (
    mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_HORIZ | mavlink.EKF_VELOCITY_VERT
    | mavlink.EKF_POS_HORIZ_REL | mavlink.EKF_POS_HORIZ_ABS | mavlink.EKF_POS_VERT_ABS
    | mavlink.EKF_PRED_POS_HORIZ_REL | mavlink.EKF_PRED_POS_HORIZ_ABS
)
EKF_ALIGNING_FLAGS = mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_VERT | mavlink.EKF_POS_VERT_ABS | mavlink.EKF_CONST_POS_MODE

# Parameters: ArduPilot names where ArduPilot has one (units as ArduPilot: cm, cm/s, mAh, s).
# SIM_* names are SITL's (libraries/SITL/SITL.cpp, ardupilot.org/dev/docs/SITL_simulation_parameters.html);
# names marked stand-in exist only here.
DEFAULT_PARAMS: Dict[str, float] = {
    "SYSID_THISMAV": 1,
    "DISARM_DELAY": 10,        # s; ArduCopter/Parameters.cpp default 10, used by Copter::auto_disarm_check (motors.cpp)
    "RTL_ALT": 1500,           # cm; default 15 m
    "RTL_LOIT_TIME": 5000,     # ms; default 5 s loiter above home before descending
    "WPNAV_SPEED": 500,        # cm/s horizontal (AC_WPNav default 5 m/s)
    "WPNAV_SPEED_UP": 250,     # cm/s climb (default 2.5 m/s)
    "WPNAV_SPEED_DN": 150,     # cm/s descent (default 1.5 m/s)
    "WPNAV_RADIUS": 200,       # cm waypoint acceptance radius (default 2 m)
    "LAND_SPEED": 50,          # cm/s final descent (default 0.5 m/s)
    "LAND_ALT_LOW": 1000,      # cm; below it LAND descends at LAND_SPEED (default 10 m)
    # mAh. SITL's default is 3300; the stand-in flies the mission's 74 Wh (params/missions/tracking.toml
    # [battery]) as a 3S pack, 74 Wh / 11.1 V = 6667 mAh: the companion reckons its energy goal from the
    # autopilot's BATT_CAPACITY (docs/guarantee.md), and SITL's 3300 mAh does not hold the default mission.
    "BATT_CAPACITY": 6667,
    "FS_EKF_ACTION": 1,        # 1 = LAND on EKF failsafe (ArduCopter default)
    "ARMING_CHECK": 1,
    "SIM_SPEEDUP": 1,
    "SIM_WIND_SPD": 0,         # m/s
    "SIM_WIND_DIR": 180,       # deg, direction the wind comes from
    "SIM_VIB_MOT_MAX": 0,      # Hz; >0 adds motor vibration (libraries/SITL/SITL.cpp VIB_MOT_MAX)
    "SIM_VIB_MOT_MULT": 1,     # amplitude scale of motor noise (VIB_MOT_MULT)
    "SIM_BATT_VOLTAGE": 12.6,  # V full pack (SITL default)
    "SIM_BATT_CAP_AH": 0,      # Ah; 0 = use BATT_CAPACITY
    "SIM_GPS_DISABLE": 0,      # 1 = GPS 1 off (libraries/SITL/SITL.cpp GPS_DISABLE)
    "SIM_BATT_PCT": -1,        # stand-in: write 0..100 to set the state of charge now
    "SIM_OBST_DIST": 0,        # stand-in: write d>0 to place an obstacle d m ahead; 0 removes it
    "SIM_OBST_ORIENT": 0,      # stand-in: DISTANCE_SENSOR orientation (MAV_SENSOR_ORIENTATION, 0 = forward)
}

# Stream messages: default interval (ms) standing in for the SRx_* stream rates. ArduPilot maps each
# MAVLink id to an ap_message (GCS_MAVLINK::mavlink_id_to_ap_message_id, GCS_Common.cpp); ids with no
# mapping are refused by MAV_CMD_SET_MESSAGE_INTERVAL with "No ap_message for mavlink id (%u)".
DEFAULT_INTERVALS_MS: Dict[int, int] = {
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 500,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 500,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 250,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 250,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: 500,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 1000,
    mavlink.MAVLINK_MSG_ID_VIBRATION: 1000,
    mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 1000,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1000,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: 1000,
    mavlink.MAVLINK_MSG_ID_WIND: 1000,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: 200,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 5000,
    mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: 5000,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: -1,   # off by default, as with SR*_POSITION on most links
}
# Ids ArduPilot maps to an ap_message that the stand-in accepts interval requests for but never generates.
KNOWN_NOT_GENERATED = {
    mavlink.MAVLINK_MSG_ID_RAW_IMU, mavlink.MAVLINK_MSG_ID_SCALED_IMU, mavlink.MAVLINK_MSG_ID_SCALED_PRESSURE,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, mavlink.MAVLINK_MSG_ID_RC_CHANNELS, mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT, mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED,
    mavlink.MAVLINK_MSG_ID_TERRAIN_REPORT, mavlink.MAVLINK_MSG_ID_AHRS, mavlink.MAVLINK_MSG_ID_POWER_STATUS,
    mavlink.MAVLINK_MSG_ID_MEMINFO, mavlink.MAVLINK_MSG_ID_RANGEFINDER, mavlink.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS,
}
HEARTBEAT_INTERVAL_S = 1.0

# Mission protocol timings (libraries/GCS_MAVLink/MissionItemProtocol.h/.cpp).
MISSION_UPLOAD_TIMEOUT_S = 8.0      # upload_timeout_ms = 8000
MISSION_REREQUEST_S = 1.0           # wp_recv_timeout_ms = 1000 + stream slowdown
MISSION_MAX_ITEMS = 700             # stand-in storage limit (AP_Mission::num_commands_max on SITL is larger)
STREAM_SLOWDOWN_DURING_TRANSFER = 4  # GCS_MAVLINK::get_reschedule_interval_ms: interval *= 4 while requesting items

SUPPORTED_FRAMES = {
    mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_INT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, mavlink.MAV_FRAME_MISSION,
}
NAV_COMMANDS = {
    mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_LOITER_UNLIM,
    mavlink.MAV_CMD_NAV_SPLINE_WAYPOINT, mavlink.MAV_CMD_NAV_DELAY,
}
DO_COMMANDS = {
    mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_DO_SET_ROI, mavlink.MAV_CMD_DO_SET_ROI_LOCATION,
    mavlink.MAV_CMD_DO_SET_ROI_NONE, mavlink.MAV_CMD_CONDITION_YAW, mavlink.MAV_CMD_CONDITION_DELAY,
    mavlink.MAV_CMD_DO_JUMP, mavlink.MAV_CMD_DO_SET_SERVO, mavlink.MAV_CMD_DO_DIGICAM_CONTROL,
    mavlink.MAV_CMD_DO_MOUNT_CONTROL, mavlink.MAV_CMD_IMAGE_START_CAPTURE, mavlink.MAV_CMD_IMAGE_STOP_CAPTURE,
    mavlink.MAV_CMD_VIDEO_START_CAPTURE, mavlink.MAV_CMD_VIDEO_STOP_CAPTURE, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
}
