"""topdress.ecu."""
