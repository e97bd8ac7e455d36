"""GNSS input shared by the terminal, the log tools and replay: NMEA decoding, speed tracking."""
