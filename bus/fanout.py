"""One Zenoh subscriber per key expression in a process, shared by every subscription it covers.

zenoh-python runs a Python callback on a thread of its own per subscriber (a channel and a
thread: ``Callback(f, indirect=True)``), so the seven subscriptions of one ``sonibus run``
to a robot's frame woke seven threads a frame, each converting the key and copying the
payload. ``Fanout`` declares one Zenoh subscriber per key expression (as ``keys.expr``
wrote it) and gives each sample to every subscription to it, in the order they joined,
on that one thread: the key converted once, the payload copied once (and only if a
subscription's size limit lets it through; past its limit a subscription gets
``codec.Oversize``). What one subscription's ``take`` raises does not keep the sample
from the others: it is raised again, to Zenoh, once they all had it.

A subscription whose key expression a broader one includes (``pepper/frame`` in
``*/frame``) is served by the broader one's Zenoh subscriber, if the process has one or
has planned to subscribe to it (``plan``: the runner plans its nodes' key expressions
before any starts), and given only the samples whose keys its own key expression
intersects (Zenoh's own matching, ``zenoh.KeyExpr.intersects``, as its own subscriber
would be given). A subscription never moves from one Zenoh subscriber to another: two
subscribers' threads deliver the same sample at different moments and Zenoh gives a
sample nothing to tell it by, so no move could be made without a sample twice or lost
(docs/design.md, "One Zenoh subscriber per key expression"). So a broader subscription
that comes after a narrower one gets a subscriber of its own, and a Zenoh subscriber
stays, as broad as it was declared, while any subscription it serves lives.

>>> class Subscriber:  # what Zenoh's ``declare_subscriber`` gives back (here: no session)
...     def __init__(self, keyexpr): self.keyexpr = keyexpr
...     def undeclare(self): print("undeclared", self.keyexpr)
>>> fanout = Fanout(lambda keyexpr, callback: Subscriber(keyexpr))
>>> fanout.plan(["*/frame"])
>>> a = fanout.join("pepper/frame", lambda key, payload, sample: None, lambda key, size: True)
>>> b = fanout.join("*/frame", lambda key, payload, sample: None, lambda key, size: True)
>>> fanout.declared, fanout.subscriptions("*/frame"), a.via
(1, 2, '*/frame')
>>> b.undeclare(); a.undeclare()
undeclared */frame
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from typing import Any

import zenoh

from .codec import Oversize

# what a subscription is handed for each sample: ``take(key, payload, sample)``, the payload as
# bytes or, past the subscription's limit, ``Oversize``; ``sample`` for what else it wants
# (the attachment of another protocol's traffic)
Take = Callable[[str, "bytes | Oversize", Any], Any]
Fits = Callable[[str, int], bool]  # whether a payload of this size on this key is kept whole
Direct = Callable[[str, "bytes | Oversize"], Any]  # a take that may decline a sample (falsy): ``join``'s ``take``
Fails = Callable[[Exception], None]  # what a take's exception is handed to (``Bus``: its node's ``on_error``)
MAX_ROUTES = 1024  # keys whose subscriptions a Zenoh subscriber remembers (keys come from the network)


class Subscription:
    """One subscription sharing a Zenoh subscriber (``via``: that subscriber's key expression,
    ``keyexpr`` or one that includes it); ``undeclare`` ends it (the last one a Zenoh
    subscriber serves undeclares it)."""

    __slots__ = ("_fanout", "direct", "fails", "fits", "keyexpr", "live", "take", "via", "whole")

    def __init__(self, fanout: Fanout, keyexpr: str, take: Take, fits: Fits, whole: int = -1,
                 fails: Fails | None = None, direct: Direct | None = None) -> None:
        self.keyexpr, self.take, self.fits, self.live, self._fanout = keyexpr, take, fits, True, fanout
        self.via, self.whole, self.fails, self.direct = keyexpr, whole, fails, direct

    def undeclare(self) -> None:
        self._fanout._leave(self)

    def __repr__(self) -> str:
        via = f" via {self.via!r}" if self.via != self.keyexpr else ""
        return f"<Subscription {self.keyexpr!r}{via}{'' if self.live else ' undeclared'}>"


class _Members:
    """A Zenoh subscriber's subscriptions, replaced whole on a change (the callback reads them
    without a lock): ``all`` in the order they joined, and, if some are narrower than the
    subscriber (``narrower``), which of them each key goes to (``routes``, filled as keys come)."""

    __slots__ = ("all", "narrower", "routes")

    def __init__(self, keyexpr: str, subscriptions: tuple[Subscription, ...]) -> None:
        self.all = subscriptions
        self.narrower = {s: zenoh.KeyExpr(s.keyexpr) for s in subscriptions if s.keyexpr != keyexpr}
        self.routes: dict[str, tuple[Subscription, ...]] = {}

    def route(self, key: str) -> tuple[Subscription, ...]:
        """The subscriptions a sample on ``key`` goes to: those of the subscriber's own key
        expression, and those narrower whose key expression intersects ``key``."""
        routed = self.routes.get(key)
        if routed is None:
            narrower = self.narrower
            routed = tuple(s for s in self.all if s not in narrower or narrower[s].intersects(key))
            if len(self.routes) < MAX_ROUTES:
                self.routes[key] = routed
        return routed


class _Shared:
    """A key expression's Zenoh subscriber and the subscriptions it serves."""

    __slots__ = ("expr", "keyexpr", "members", "subscriber")

    def __init__(self, keyexpr: str) -> None:
        self.keyexpr, self.expr = keyexpr, zenoh.KeyExpr(keyexpr)
        self.subscriber: Any = None
        self.members = _Members(keyexpr, ())

    def dispatch(self, sample: Any) -> None:
        """Zenoh's callback: ``sample`` to every subscription it is for, each as its limit says."""
        key = str(sample.key_expr)
        members = self.members
        subscriptions = members.route(key) if members.narrower else members.all
        if not subscriptions:
            return
        payload = sample.payload
        size = len(payload)
        data: bytes | None = None
        failed: Exception | None = None
        for subscription in subscriptions:
            if not subscription.live:  # (undeclared while this sample went round)
                continue
            # (``whole``: a size kept whole without a call, every frame of every node; issue 35)
            if size <= subscription.whole or subscription.fits(key, size):
                if data is None:
                    data = payload.to_bytes()
                kept: bytes | Oversize = data
            else:
                kept = Oversize(size)
            try:
                # (``direct`` called here, not by a ``take`` that forwards: a Python call less a frame; issue 35)
                direct = subscription.direct
                if direct is None or not direct(key, kept):
                    subscription.take(key, kept, sample)
            except Exception as exc:  # the others still get it; then Zenoh hears of it, as before sharing
                # (the guard here, not a wrapper around each take: a Python call less a sample; issue 35)
                fails = subscription.fails
                if fails is None:
                    failed = failed or exc
                    continue
                try:
                    fails(exc)
                except Exception as again:
                    failed = failed or again
        if failed is not None:
            raise failed

    def change(self, subscriptions: tuple[Subscription, ...]) -> None:
        self.members = _Members(self.keyexpr, subscriptions)


class Fanout:
    """The subscriptions of one session, one Zenoh subscriber per key expression.
    ``declare(keyexpr, callback)`` declares a Zenoh subscriber (``Bus`` passes its session's)."""

    def __init__(self, declare: Callable[[str, Callable[[Any], None]], Any]) -> None:
        self._declare = declare
        self._lock = threading.Lock()  # joins and leaves come from every node's threads
        self._shared: dict[str, _Shared] = {}
        self._planned: dict[str, zenoh.KeyExpr] = {}
        self.declared = 0  # Zenoh subscribers declared so far (what sharing saves, for tests and benches)

    def plan(self, keyexprs: Iterable[str]) -> None:
        """Key expressions (``keys.expr``'s) the process will subscribe to: a subscription one of
        them includes, joining before it, is served by a Zenoh subscriber to the broadest of them
        that includes it, declared then, and the broader subscription joins that one later."""
        planned = {keyexpr: zenoh.KeyExpr(keyexpr) for keyexpr in keyexprs}
        with self._lock:
            self._planned = {**planned, **self._planned}

    def join(self, keyexpr: str, take: Take, fits: Fits, whole: int = -1, fails: Fails | None = None,
             direct: Direct | None = None) -> Subscription:
        """A subscription to ``keyexpr`` (a ``keys.expr``): ``take(key, payload, sample)`` for each
        sample of it on a Zenoh subscriber's thread, the payload whole where it is at most ``whole``
        bytes or ``fits(key, size)``; with ``direct``, ``direct(key, payload)`` first, and ``take`` only
        for what it declines (returns falsy). What they raise is handed to ``fails`` (if given: what
        that raises, or the exception itself without it, is raised to Zenoh once the others had it)."""
        subscription = Subscription(self, keyexpr, take, fits, whole, fails, direct)
        with self._lock:
            shared = self._serving(keyexpr)
            if shared is None:
                via = self._broadest_planned(keyexpr)
                shared = _Shared(via)
                # (joined before Zenoh is asked: a sample that comes as soon as it is declared is this one's;
                # under the lock: a second node joining now must find this subscriber, not declare one)
                subscription.via = via
                shared.change((subscription,))
                shared.subscriber = self._declare(via, shared.dispatch)
                self._shared[via] = shared
                self.declared += 1
            else:
                subscription.via = shared.keyexpr
                shared.change((*shared.members.all, subscription))
        return subscription

    def _serving(self, keyexpr: str) -> _Shared | None:
        """The Zenoh subscriber of ``keyexpr``, or of one that includes it (under the lock)."""
        shared = self._shared.get(keyexpr)
        if shared is not None:
            return shared
        wanted = zenoh.KeyExpr(keyexpr)
        return next((shared for shared in self._shared.values() if shared.expr.includes(wanted)), None)

    def _broadest_planned(self, keyexpr: str) -> str:
        """The planned key expression to declare for ``keyexpr``: one that includes it and that no
        other planned one includes (``keyexpr`` itself if none does)."""
        if not self._planned:
            return keyexpr
        wanted = zenoh.KeyExpr(keyexpr)
        covering = [k for k, expr in self._planned.items() if expr.includes(wanted)]
        for candidate in covering:
            expr = self._planned[candidate]
            if not any(other != candidate and self._planned[other].includes(expr)
                       and not expr.includes(self._planned[other]) for other in covering):
                return candidate
        return keyexpr

    def subscriptions(self, keyexpr: str) -> int:
        """How many subscriptions the Zenoh subscriber declared for ``keyexpr`` serves now."""
        with self._lock:
            shared = self._shared.get(keyexpr)
            return len(shared.members.all) if shared is not None else 0

    def _leave(self, subscription: Subscription) -> None:
        with self._lock:
            if not subscription.live:
                return
            subscription.live = False
            shared = self._shared[subscription.via]
            shared.change(tuple(s for s in shared.members.all if s is not subscription))
            if shared.members.all:
                return
            del self._shared[subscription.via]
        # (not under the lock: a callback of this subscriber that joins or leaves must not wait on it)
        shared.subscriber.undeclare()
