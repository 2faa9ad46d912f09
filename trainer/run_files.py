"""Reading a run folder's JSON files (summary.json, config.json, task.json, …) so that a missing or
damaged one is an error naming the file, for every command that reads run folders."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


class RunFolderError(ValueError):
    """A run folder's file cannot be read as what it should hold; the message names the file."""


def read_json_object(path: Path) -> dict[str, Any]:
    """`path`'s JSON object; RunFolderError naming the file and why if it is missing, not JSON or
    not an object (a file cut short by a full disk, or written by hand)."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise RunFolderError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunFolderError(f"{path}: not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise RunFolderError(f"{path}: not a JSON object")
    return data
