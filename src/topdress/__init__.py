"""topdress: variable-rate topdressing of corn with dual (GNSS + ground wheel) speed measurement."""

__version__ = "0.1.0"
