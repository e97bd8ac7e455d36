"""The session log (SQLite) and what is read back from it: raw events and state CSV exports,
the summary, and replay of a session through the C core."""
