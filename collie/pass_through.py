"""Flags one command hands on to `collie train` (`collie up --train-args`, `collie sweep -- …`):
those naming an option the handing command sets itself are refused. Given again they would win
(argparse keeps an option's last value) and contradict it: a run written elsewhere than the
command looks, a seed unlike the one its folder is named by."""

from __future__ import annotations

from collections.abc import Collection, Iterable


def owned_flags(flags: Iterable[str], owned: Collection[str], known: Collection[str] = ()) -> list[str]:
    """The flags among `flags` that set an option of `owned`: `--out X`, `--out=X`, or an
    abbreviation argparse expands to it (a prefix of that option alone among the `known` ones)."""
    found = []
    for given in flags:
        name = given.split("=")[0]
        if not name.startswith("--"):
            continue
        if name in owned:
            found.append(given)
        elif name not in known:
            expands = [option for option in known if option.startswith(name)]
            if len(expands) == 1 and expands[0] in owned:
                found.append(given)
    return found
