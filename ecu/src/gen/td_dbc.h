/* Generated from protocol/topdress.dbc by scripts/gen_proto.py: never edit by hand. */
#ifndef TD_DBC_H
#define TD_DBC_H

/* Frame identifiers (29-bit). */
#define TD_ID_ECU_STATUS 0x185C6465u
#define TD_ID_PC_COMMAND 0x0A5C6465u
#define TD_ID_ECU_DIAG 0x185D6465u
#define TD_ID_ECU_SPEEDS 0x185E6465u
#define TD_ID_ECU_TARGETS 0x185F6465u
#define TD_ID_PC_PARAM_SET 0x0A606465u
#define TD_ID_ECU_PARAM_ACK 0x18616465u
#define TD_ID_PC_CAL_COMMAND 0x0A646465u
#define TD_ID_ECU_CAL_STATUS 0x18656465u
#define TD_ID_PC_GNSS_TIME 0x0A626465u
#define TD_ID_ECU_FUSED 0x18636465u
#define TD_ID_ECU_FUSED_AUX 0x18666465u
#define TD_ID_ECU_GNSS_LAG 0x18696465u
#define TD_ID_ECU_IDENT 0x18676465u
#define TD_ID_ECU_CAN_HEALTH 0x186A6465u
#define TD_ID_ECU_FAULT_RECORD 0x186B6465u
/* Every frame's identifier: X(TD_ID_<FRAME>). */
#define TD_FRAME_IDS(X) \
    X(TD_ID_ECU_STATUS) \
    X(TD_ID_PC_COMMAND) \
    X(TD_ID_ECU_DIAG) \
    X(TD_ID_ECU_SPEEDS) \
    X(TD_ID_ECU_TARGETS) \
    X(TD_ID_PC_PARAM_SET) \
    X(TD_ID_ECU_PARAM_ACK) \
    X(TD_ID_PC_CAL_COMMAND) \
    X(TD_ID_ECU_CAL_STATUS) \
    X(TD_ID_PC_GNSS_TIME) \
    X(TD_ID_ECU_FUSED) \
    X(TD_ID_ECU_FUSED_AUX) \
    X(TD_ID_ECU_GNSS_LAG) \
    X(TD_ID_ECU_IDENT) \
    X(TD_ID_ECU_CAN_HEALTH) \
    X(TD_ID_ECU_FAULT_RECORD) \
    /* end */

/* EcuStatus.RunState */
#define TD_RUN_STOPPED 0x00u
#define TD_RUN_RUNNING 0x0Au

/* EcuDiag.FaultWord: one bit each, lowest first */
#define TD_FAULT_CMD_TIMEOUT (1u << 0)
#define TD_FAULT_GNSS_LOST (1u << 1)
#define TD_FAULT_WHEEL_ENCODER (1u << 2)
#define TD_FAULT_UPPER_BLOCKED (1u << 3)
#define TD_FAULT_LOWER_BLOCKED (1u << 4)
#define TD_FAULT_UPPER_FAN_LOW (1u << 5)
#define TD_FAULT_LOWER_FAN_LOW (1u << 6)
#define TD_FAULT_NO_SPEED (1u << 7)
#define TD_FAULT_GNSS_FROZEN (1u << 8)

/** EcuDiag.SpeedSource */
typedef enum { TD_SRC_WHEEL = 0, TD_SRC_GNSS = 1, TD_SRC_NONE = 2, TD_SRC_FUSED = 3 } td_source_t;

/** EcuDiag.SpeedMode */
typedef enum { TD_MODE_DUAL = 0, TD_MODE_WHEEL_ONLY = 1, TD_MODE_GNSS_ONLY = 2, TD_MODE_FUSED = 3 } td_speed_mode_t;

/** EcuDiag.SwitchCompare */
typedef enum { TD_CMP_GNSS = 0, TD_CMP_WHEEL = 1 } td_compare_t;

/** EcuParamAck.AckResult */
typedef enum { TD_ACK_OK = 0, TD_ACK_UNKNOWN_PARAM = 1, TD_ACK_OUT_OF_RANGE = 2, TD_ACK_BUSY = 3, TD_ACK_INCONSISTENT = 4, TD_ACK_BAD_FRAME = 5 } td_ack_result_t;

/** EcuCalStatus.CalState */
typedef enum { TD_CAL_IDLE = 0, TD_CAL_RUNNING = 1, TD_CAL_DONE = 2, TD_CAL_ABORTED = 3 } td_cal_state_t;

/** EcuCalStatus.CalReason */
typedef enum { TD_CAL_R_NONE = 0, TD_CAL_R_RESET = 1, TD_CAL_R_RUNNING = 2, TD_CAL_R_MOVING = 3, TD_CAL_R_BLOCKED = 4, TD_CAL_R_TIMEOUT = 5, TD_CAL_R_BAD_VALUE = 6, TD_CAL_R_FANS_OFF = 7 } td_cal_reason_t;

/** EcuGnssLag.LagState */
typedef enum { TD_LAG_START = 0, TD_LAG_LEARNED = 1, TD_LAG_FIXED = 2, TD_LAG_OVERRULED = 3 } td_lag_state_t;

/** EcuIdent.Target */
typedef enum { TD_TARGET_HOST = 0, TD_TARGET_STM32F4 = 1 } td_target_t;

/** EcuIdent.Transport */
typedef enum { TD_TRANSPORT_IN_PROCESS = 0, TD_TRANSPORT_CAN = 1, TD_TRANSPORT_SLCAN_HIL = 2 } td_transport_t;

/** EcuIdent.ResetCause */
typedef enum { TD_RESET_UNKNOWN = 0, TD_RESET_POWER_ON = 1, TD_RESET_PIN = 2, TD_RESET_WATCHDOG = 3, TD_RESET_HARD_FAULT = 4, TD_RESET_SOFTWARE = 5, TD_RESET_BROWN_OUT = 6 } td_reset_cause_t;

/* PcParamSet: one row a parameter, id order: X(id, signal, td_params_t field, storage,
 * resolution, raw minimum, raw maximum). */
#define TD_PARAM_COUNT 39u
#define TD_PARAM_TABLE(X) \
    X(1, WorkingWidth, working_width_m, TD_PF32, 0.001f, 500u, 30000u) \
    X(2, UpperKgPerRev, kg_per_rev[0], TD_PF32, 0.0001f, 10u, 50000u) \
    X(3, LowerKgPerRev, kg_per_rev[1], TD_PF32, 0.0001f, 10u, 50000u) \
    X(4, WheelRadius, wheel_radius_m, TD_PF32, 0.0001f, 200u, 10000u) \
    X(5, WheelPulsesPerRev, wheel_ppr, TD_PU16, 1.0f, 1u, 10000u) \
    X(6, QueueLength, queue_len, TD_PU8, 1.0f, 2u, 16u) \
    X(7, CvWindow, cv_window, TD_PU8, 1.0f, 2u, 16u) \
    X(8, CvThreshold, cv_threshold_pct, TD_PF32, 0.01f, 10u, 5000u) \
    X(9, SwitchSpeed, switch_speed_kmh, TD_PF32, 0.01f, 0u, 2500u) \
    X(10, SpeedMode, speed_mode, TD_PU8, 1.0f, 0u, 3u) \
    X(11, SwitchCompare, switch_compare, TD_PU8, 1.0f, 0u, 1u) \
    X(12, PidKp, pid_kp, TD_PF32, 0.0001f, 0u, 100000u) \
    X(13, PidKi, pid_ki, TD_PF32, 0.0001f, 0u, 100000u) \
    X(14, PidKd, pid_kd, TD_PF32, 0.0001f, 0u, 100000u) \
    X(15, PidKff, pid_kff, TD_PF32, 1e-05f, 0u, 100000u) \
    X(16, CmdTimeout, cmd_timeout_ms, TD_PU16, 1.0f, 100u, 10000u) \
    X(17, GnssTimeout, gnss_timeout_ms, TD_PU16, 1.0f, 100u, 10000u) \
    X(18, MinWorkSpeed, min_work_speed_kmh, TD_PF32, 0.01f, 0u, 1000u) \
    X(19, WheelUpdatePeriod, wheel_update_ms, TD_PU16, 1.0f, 50u, 5000u) \
    X(20, WheelSamples, wheel_samples, TD_PU8, 1.0f, 1u, 16u) \
    X(21, MeterCountsPerRev, meter_counts_per_rev, TD_PU16, 1.0f, 1u, 65535u) \
    X(22, FanMinSpeed, fan_min_rpm, TD_PU16, 1.0f, 0u, 6000u) \
    X(23, FanPulsesPerRev, fan_ppr, TD_PU8, 1.0f, 1u, 255u) \
    X(24, EncFaultGnssSpeed, enc_fault_gnss_kmh, TD_PF32, 0.01f, 50u, 2500u) \
    X(25, EncFaultTime, enc_fault_time_ms, TD_PU16, 1.0f, 100u, 30000u) \
    X(26, BlockedTime, blocked_time_ms, TD_PU16, 1.0f, 100u, 30000u) \
    X(27, StatusPeriod, status_period_ms, TD_PU16, 1.0f, 20u, 1000u) \
    X(28, SlipComp, slip_comp, TD_PU8, 1.0f, 0u, 2u) \
    X(29, GnssLag, gnss_lag_ms, TD_PU16, 1.0f, 0u, 3000u) \
    X(30, LeadMeter, lead_meter_ms, TD_PU16, 1.0f, 0u, 3000u) \
    X(31, LeadAirLine, lead_air_ms, TD_PU16, 1.0f, 0u, 5000u) \
    X(32, FusedJerk, fused_jerk_ms3, TD_PF32, 0.01f, 1u, 5000u) \
    X(33, FusedGnssStd, fused_gnss_std_kmh, TD_PF32, 0.01f, 1u, 1000u) \
    X(34, FusedWheelNoise, fused_wheel_noise_pct, TD_PF32, 0.01f, 10u, 5000u) \
    X(35, WheelStopTime, wheel_stop_ms, TD_PU16, 1.0f, 20u, 5000u) \
    X(36, DriveAdapt, drive_adapt, TD_PU8, 1.0f, 0u, 1u) \
    X(37, MeterTau, meter_tau_ms, TD_PU16, 1.0f, 0u, 2000u) \
    X(38, LeadStop, lead_stop_ms, TD_PU16, 1.0f, 0u, 5000u) \
    X(39, GnssLagAuto, gnss_lag_auto, TD_PU8, 1.0f, 0u, 1u) \
    /* end */

#endif
