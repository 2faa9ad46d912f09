"""What a `collie up` stack's folder (OUT) holds, for the stack and for the tools that read it
(`collie archive` names a stack's run by its folder)."""

from __future__ import annotations

STACK_LOCK = "up.lock"  # held by the stack and every part of it; marks a folder as a stack's
STACK_RUN = "trainer"  # the run folder, the trainer's --out
