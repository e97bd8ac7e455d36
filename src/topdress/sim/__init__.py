"""topdress.sim."""
