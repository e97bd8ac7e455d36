"""topdress.protocol."""
