"""Device access: line sources (serial port, file, stdin, a fake with fault knobs), the CAN
bus, the ports this machine has."""
