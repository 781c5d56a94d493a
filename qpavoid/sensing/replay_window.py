"""An anti-replay window (RFC 4303, section 3.4.3): which sequence numbers of one sender
and key were seen (:class:`~qpavoid.sensing.signing.Verifier` keeps one per sensor and key)."""

from __future__ import annotations

__all__ = ["REPLAY_WINDOW", "ReplayWindow"]

#: Sequence numbers accepted below the highest seen (RFC 4303's default window, 64): the
#: bodies of one frame may arrive in any order; a number seen or below the window is a
#: replay.
REPLAY_WINDOW = 64


class ReplayWindow:
    """Which sequence numbers of one sender were seen: the highest, and a bit for each of
    the :data:`REPLAY_WINDOW` below it (RFC 4303, section 3.4.3). :meth:`seen` and
    :meth:`mark` are apart so that only a datagram that passed every other check moves it."""

    def __init__(self, size: int = REPLAY_WINDOW):
        self.size, self.top, self._bits = size, -1, 0

    def seen(self, sequence: int) -> bool:
        """True if ``sequence`` was marked, or lies below the window (a replay)."""
        offset = self.top - sequence
        return offset >= self.size or (offset >= 0 and bool((self._bits >> offset) & 1))

    def mark(self, sequence: int) -> None:
        """Mark ``sequence`` seen (one that :meth:`seen` let through)."""
        shift = sequence - self.top
        if shift > 0:  # a new highest: the window slides (never by more than its size)
            self._bits = (
                ((self._bits << shift) | 1) & ((1 << self.size) - 1) if shift < self.size else 1
            )
            self.top = sequence
        else:
            self._bits |= 1 << -shift

    def accept(self, sequence: int) -> bool:
        """True, and ``sequence`` marked, if it was not seen; False for a replay."""
        if self.seen(sequence):
            return False
        self.mark(sequence)
        return True
