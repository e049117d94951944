"""One Zenoh subscriber per key expression in a process, shared by every subscription to it.

zenoh-python runs a Python callback on a thread of its own per subscriber (a channel and a
thread: ``Callback(f, indirect=True)``), so the seven subscriptions of one ``sonibus run``
to a robot's frame woke seven threads a frame, each converting the key and copying the
payload. ``Fanout`` declares one Zenoh subscriber per key expression (as ``keys.expr``
wrote it) and gives each sample to every subscription to it, in the order they joined,
on that one thread: the key converted once, the payload copied once (and only if a
subscription's size limit lets it through; past its limit a subscription gets
``codec.Oversize``). What one subscription's ``take`` raises does not keep the sample
from the others: it is raised again, to Zenoh, once they all had it.

>>> class Subscriber:  # what Zenoh's ``declare_subscriber`` gives back (here: no session)
...     def undeclare(self): print("undeclared")
>>> fanout = Fanout(lambda keyexpr, callback: Subscriber())
>>> a = fanout.join("pepper/frame", lambda key, payload, sample: None, lambda key, size: True)
>>> b = fanout.join("pepper/frame", lambda key, payload, sample: None, lambda key, size: True)
>>> fanout.declared, fanout.subscriptions("pepper/frame")
(1, 2)
>>> a.undeclare(); b.undeclare()
undeclared
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from .codec import Oversize

# what a subscription is handed for each sample: ``take(key, payload, sample)``, the payload as
# bytes or, past the subscription's limit, ``Oversize``; ``sample`` for what else it wants
# (the attachment of another protocol's traffic)
Take = Callable[[str, "bytes | Oversize", Any], Any]
Fits = Callable[[str, int], bool]  # whether a payload of this size on this key is kept whole


class Subscription:
    """One subscription sharing its key expression's Zenoh subscriber; ``undeclare`` ends it
    (the last one of a key expression undeclares the Zenoh subscriber)."""

    __slots__ = ("_fanout", "fits", "keyexpr", "live", "take")

    def __init__(self, fanout: Fanout, keyexpr: str, take: Take, fits: Fits) -> None:
        self.keyexpr, self.take, self.fits, self.live, self._fanout = keyexpr, take, fits, True, fanout

    def undeclare(self) -> None:
        self._fanout._leave(self)

    def __repr__(self) -> str:
        return f"<Subscription {self.keyexpr!r}{'' if self.live else ' undeclared'}>"


class _Shared:
    """A key expression's Zenoh subscriber and its subscriptions (a tuple, replaced whole on a
    change, so the callback reads it without a lock)."""

    __slots__ = ("subscriber", "subscriptions")

    def __init__(self) -> None:
        self.subscriber: Any = None
        self.subscriptions: tuple[Subscription, ...] = ()

    def dispatch(self, sample: Any) -> None:
        """Zenoh's callback: ``sample`` to every subscription, each as its limit says."""
        key = str(sample.key_expr)
        payload = sample.payload
        size = len(payload)
        data: bytes | None = None
        failed: Exception | None = None
        for subscription in self.subscriptions:
            if not subscription.live:  # (undeclared while this sample went round)
                continue
            if subscription.fits(key, size):
                if data is None:
                    data = payload.to_bytes()
                kept: bytes | Oversize = data
            else:
                kept = Oversize(size)
            try:
                subscription.take(key, kept, sample)
            except Exception as exc:  # the others still get it; then Zenoh hears of it, as before sharing
                failed = failed or exc
        if failed is not None:
            raise failed


class Fanout:
    """The subscriptions of one session, one Zenoh subscriber per key expression.
    ``declare(keyexpr, callback)`` declares a Zenoh subscriber (``Bus`` passes its session's)."""

    def __init__(self, declare: Callable[[str, Callable[[Any], None]], Any]) -> None:
        self._declare = declare
        self._lock = threading.Lock()  # joins and leaves come from every node's threads
        self._shared: dict[str, _Shared] = {}
        self.declared = 0  # Zenoh subscribers declared so far (what sharing saves, for tests and benches)

    def join(self, keyexpr: str, take: Take, fits: Fits) -> Subscription:
        """A subscription to ``keyexpr`` (a ``keys.expr``): ``take(key, payload, sample)`` for each
        sample on the Zenoh subscriber's thread, the payload whole where ``fits(key, size)``."""
        subscription = Subscription(self, keyexpr, take, fits)
        with self._lock:
            shared = self._shared.get(keyexpr)
            if shared is None:
                shared = _Shared()
                # (joined before Zenoh is asked: a sample that comes as soon as it is declared is this one's;
                # under the lock: a second node joining now must find this subscriber, not declare one)
                shared.subscriptions = (subscription,)
                shared.subscriber = self._declare(keyexpr, shared.dispatch)
                self._shared[keyexpr] = shared
                self.declared += 1
            else:
                shared.subscriptions += (subscription,)
        return subscription

    def subscriptions(self, keyexpr: str) -> int:
        """How many subscriptions share ``keyexpr``'s Zenoh subscriber now."""
        with self._lock:
            shared = self._shared.get(keyexpr)
            return len(shared.subscriptions) if shared is not None else 0

    def _leave(self, subscription: Subscription) -> None:
        with self._lock:
            if not subscription.live:
                return
            subscription.live = False
            shared = self._shared[subscription.keyexpr]
            shared.subscriptions = tuple(s for s in shared.subscriptions if s is not subscription)
            if shared.subscriptions:
                return
            del self._shared[subscription.keyexpr]
        # (not under the lock: a callback of this subscriber that joins or leaves must not wait on it)
        shared.subscriber.undeclare()
