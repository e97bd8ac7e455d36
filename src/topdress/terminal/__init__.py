"""The cab terminal's control loop: GNSS and crop lines and the ECU's frames in, the rate per
layer out over CAN, a Snapshot and a state row every tick; the operator's desk (commands,
alarms, counters, calibration wizards, settings) inside it."""
