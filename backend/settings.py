"""Service settings, read from the environment with the COLLIE_ prefix (e.g. COLLIE_DATABASE_URL)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="COLLIE_", extra="ignore")

    database_url: str = "sqlite:///collie.db"
    # Bootstrap tokens: when set, a principal of that role is created (or re-keyed) at start.
    operator_token: SecretStr | None = None
    trainer_token: SecretStr | None = None
    labeler_token: SecretStr | None = None
    # The oracle teacher's own labeler (compose's teacher profile): a principal apart from `labeler`,
    # named as `collie up --teacher oracle` names its teacher's. Empty: none (compose's unset value).
    teacher_token: SecretStr | None = None

    lease_s: float = Field(default=120.0, gt=0, description="how long a claim holds a query")
    max_session_bytes: int = Field(default=128 * 1024 * 1024, description="body limit for posting a session")
    max_rollouts_bytes: int = Field(default=16 * 1024 * 1024, description="body limit for posting rollouts")
    max_body_bytes: int = Field(default=1024 * 1024, description="body limit for every other request")
    max_queries_per_session: int = 4096
    token_cache_s: float = Field(default=5.0, description="how long a resolved token is trusted without a read")
    max_streams_per_token: int = Field(default=32, ge=1, description="open SSE streams one token may hold")
    stream_poll_s: float = Field(default=1.0, description="fallback re-read for events written by other processes")
    sqlite_synchronous: Literal["NORMAL", "FULL"] = Field(
        default="FULL", description="FULL: an acknowledged label survives a power cut (NORMAL: a process crash)"
    )
    web_dir: Path | None = Field(default=None, description="static dashboard to serve at / when present")

    @field_validator("teacher_token", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        return None if value == "" else value
