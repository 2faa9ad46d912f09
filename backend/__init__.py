"""The labeling service: FastAPI over SQLAlchemy (SQLite file by default). Imports no torch and no
MuJoCo, so it starts in about a second and can be deployed alone."""

__version__ = "0.1.0"
