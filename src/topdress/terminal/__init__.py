"""topdress.terminal."""
