"""The farm office: every cab's sessions in one PostgreSQL + PostGIS database (docs/office.md)."""
