"""GNSS, in one place: NMEA decoding (the terminal, the log tools, replay), sentences written
(the simulated receiver), speed tracking, UTC from the fixes."""
