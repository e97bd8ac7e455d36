"""topdress.log."""
