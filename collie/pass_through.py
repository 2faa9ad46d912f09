"""Flags one command hands on to `collie train` (`collie up --train-args`, `collie sweep -- …`):
those naming an option the handing command sets itself are refused. Given again they would win
(argparse keeps an option's last value) and contradict it: a run written elsewhere than the
command looks, a seed unlike the one its folder is named by. `collie train` takes no abbreviated
flag (collie/cli.py), so a flag is matched by its exact name."""

from __future__ import annotations

from collections.abc import Collection, Iterable


def owned_flags(flags: Iterable[str], owned: Collection[str]) -> list[str]:
    """The flags among `flags` that set an option of `owned`: `--out X` or `--out=X`."""
    return [given for given in flags if given.split("=")[0] in owned]
