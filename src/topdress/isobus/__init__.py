"""ISOBUS (ISO 11783) pieces of the terminal side: the machine's device description (DDOP)."""
