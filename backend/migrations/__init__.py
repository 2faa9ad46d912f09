"""Alembic migrations, applied programmatically at service start (see backend.migrate)."""
