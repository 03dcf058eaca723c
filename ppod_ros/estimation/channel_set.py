"""The feedback's channel set: which channels the live loop uses, changed only on persistent evidence.

Every estimate (:meth:`AccelEstimator.from_summaries`) decides alone which channels it drops: a
grossly broken channel is out of that estimate at once. The channel set of a running loop must not
follow that decision estimate by estimate: on a real array the estimate depends a little on which
channels are used, so a set that flickers makes the learning loop chase its own sensor selection.
:class:`ChannelSet` removes a channel only after it was dropped in ``drop_after`` consecutive
estimates, and restores it only after ``restore_after`` consecutive estimates in which it would have
been kept; every change is reported with its reason, and the loop restarts its learning on it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ppod_ros.errors import ConfigError


@dataclass(frozen=True)
class ChannelSetSettings:
    """Hysteresis of the channel set (estimates, not seconds: the loop's own pace)."""

    #: Consecutive estimates a channel must be dropped in before it leaves the set.
    drop_after: int = 3
    #: Consecutive estimates a removed channel must pass before it rejoins (longer: rejoining costs a
    #: restart of learning, and an intermittent channel should stay out).
    restore_after: int = 10

    def __post_init__(self) -> None:
        for name in ("drop_after", "restore_after"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ConfigError(f"channel_set.{name}: expected an integer >= 1 (estimates), got {v!r}")


@dataclass(frozen=True)
class ChannelSetChange:
    """A change of the set: channels removed (name -> reason) and restored."""

    removed: dict[str, str]
    restored: tuple[str, ...]

    def describe(self) -> str:
        parts = [f"{n} removed ({why})" for n, why in self.removed.items()]
        parts += [f"{n} restored" for n in self.restored]
        return "; ".join(parts)


class ChannelSet:
    """See the module docstring.

    Parameters
    ----------
    names : sequence of str
        All channels of the layout.
    settings : ChannelSetSettings, optional
    """

    def __init__(self, names: Sequence[str], settings: ChannelSetSettings | None = None):
        self.names = tuple(names)
        self.settings = settings or ChannelSetSettings()
        self.removed: dict[str, str] = {}
        self._bad_run = dict.fromkeys(self.names, 0)
        self._good_run = dict.fromkeys(self.names, 0)
        self._last_reason: dict[str, str] = {}

    @property
    def active(self) -> tuple[str, ...]:
        """Channels in use, in layout order."""
        return tuple(n for n in self.names if n not in self.removed)

    def observe(self, status: dict[str, str]) -> ChannelSetChange | None:
        """Account one estimate over all channels (name -> "ok" or why dropped); the change, if any."""
        unknown = sorted(set(status) - set(self.names))
        if unknown:
            raise ConfigError(f"status: channels {unknown} are not in the channel set {list(self.names)}")
        removed: dict[str, str] = {}
        restored: list[str] = []
        for n in self.names:
            if n not in status:
                continue
            ok = status[n] == "ok"
            self._bad_run[n] = 0 if ok else self._bad_run[n] + 1
            self._good_run[n] = self._good_run[n] + 1 if ok else 0
            if not ok:
                self._last_reason[n] = status[n]
            if n not in self.removed and self._bad_run[n] >= self.settings.drop_after:
                removed[n] = f"dropped in {self._bad_run[n]} consecutive estimates: {self._last_reason[n]}"
            elif n in self.removed and self._good_run[n] >= self.settings.restore_after:
                restored.append(n)
        if not removed and not restored:
            return None
        self.removed.update(removed)
        for n in restored:
            del self.removed[n]
        return ChannelSetChange(removed, tuple(restored))

    def reset(self) -> None:
        """Every channel back in the set, no history (a new device session)."""
        self.removed.clear()
        self._bad_run = dict.fromkeys(self.names, 0)
        self._good_run = dict.fromkeys(self.names, 0)


__all__ = ["ChannelSet", "ChannelSetChange", "ChannelSetSettings"]
