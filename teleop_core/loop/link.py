"""The master-follower network link: delay, jitter and packet loss ([endovascular], IV-A).

Packets are datagrams: each is delayed by `delay_s` plus a jitter drawn uniformly from
[0, jitter_s], dropped with probability `loss`, and a receiver keeps only the newest
packet by send order (a late packet overtaken by a newer one is discarded, as a UDP
receiver with sequence numbers does). Between packets the receiver holds the last
value. Written here rather than taken from a network emulator (netem and friends act
on real sockets; the loop needs the same behaviour inside a deterministic simulation).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

from teleop_core._jit import njit
from teleop_core.errors import TeleopInputError
from teleop_core.loop.layout import PACKET_COMMAND, PACKET_FORCE, SCH_TICK, SCHEDULE_WIDTH

T = TypeVar("T")


@dataclass(frozen=True)
class LinkParams:
    """One direction of the link."""

    delay_s: float = 0.0
    """Fixed one-way delay; 0 is the paper's wired Ethernet (IV-A)."""
    jitter_s: float = 0.0
    """Extra delay drawn uniformly from [0, jitter_s] per packet."""
    loss: float = 0.0
    """Probability that a packet is lost, in [0, 1]."""

    def __post_init__(self) -> None:
        for name in ("delay_s", "jitter_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise TeleopInputError(f"link {name} = {value!r}; expected a finite value >= 0")
        if not (0.0 <= self.loss <= 1.0):
            raise TeleopInputError(f"link loss = {self.loss!r}; expected a probability in [0, 1]")


@dataclass
class Link(Generic[T]):
    """A one-way link carrying values of type T."""

    params: LinkParams = field(default_factory=LinkParams)
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    sent: int = 0
    lost: int = 0
    delivered: int = 0
    discarded_late: int = 0

    def __post_init__(self) -> None:
        self._queue: list[tuple[float, int, float, T]] = []
        self._newest_seq = -1
        self.value: T | None = None
        self.value_sent_at_s = math.nan

    def send(self, t_s: float, value: T) -> None:
        """Send `value` at time t_s."""
        seq = self.sent
        self.sent += 1
        p = self.params
        if p.loss > 0.0 and self.rng.random() < p.loss:
            self.lost += 1
            return
        jitter = self.rng.random() * p.jitter_s if p.jitter_s > 0.0 else 0.0
        heapq.heappush(self._queue, (t_s + p.delay_s + jitter, seq, t_s, value))

    def next_arrival_s(self) -> float:
        """When the next queued packet arrives (inf when none is in flight)."""
        return self._queue[0][0] if self._queue else math.inf

    def deliver_until(self, t_s: float) -> list[tuple[float, T]]:
        """Deliver every packet due by t_s; return (arrival time, value) of each one the
        receiver accepts, in arrival order."""
        accepted: list[tuple[float, T]] = []
        while self._queue and self._queue[0][0] <= t_s + 1e-12:
            arrival, seq, sent_at, value = heapq.heappop(self._queue)
            if seq < self._newest_seq:
                self.discarded_late += 1
                continue
            self._newest_seq = seq
            self.value = value
            self.value_sent_at_s = sent_at
            self.delivered += 1
            accepted.append((arrival, value))
        return accepted

    def receive(self, t_s: float) -> T | None:
        """Deliver every packet due by t_s; return the newest value held (None before any)."""
        self.deliver_until(t_s)
        return self.value


# The same link inside the loop's compiled kernel (the fast path): a queue of packets in
# flight per direction, and the random draws taken from a pre-drawn pool in the order
# `Link.send` takes them, so both paths deliver the same packets at the same ticks.
Q_ARRIVAL, Q_SEQ, Q_V1, Q_V2 = range(4)
QUEUE_WIDTH = 4
QUEUE_ROWS = 256
LS_COUNT, LS_NEXT_SEQ, LS_NEWEST, LS_SENT, LS_LOST, LS_DELIVERED = range(6)
LINK_STATE_SIZE = 6
LP_DELAY, LP_JITTER, LP_LOSS = range(3)  # `link_vector`
LINK_PARAM_SIZE = 3
PK_V1, PK_V2 = range(2)  # what `kernel_deliver` writes to `out`
DELIVERED_WIDTH = 2
POOL_NEXT = 0  # `pos[POOL_NEXT]`: the next unused draw of the pool


def link_vector(params: LinkParams) -> np.ndarray:
    lp = np.empty(LINK_PARAM_SIZE)
    lp[LP_DELAY], lp[LP_JITTER], lp[LP_LOSS] = params.delay_s, params.jitter_s, params.loss
    return lp


@njit(cache=True)
def kernel_send(
    queue: np.ndarray,
    ls: np.ndarray,
    lp: np.ndarray,
    pool: np.ndarray,
    pos: np.ndarray,
    t_s: float,
    v1: float,
    v2: float,
) -> None:  # pragma: no cover - compiled; exercised through TeleopLoop
    """`Link.send` on the kernel's queue; `pos[POOL_NEXT]` indexes the pool of uniform draws."""
    seq = ls[LS_NEXT_SEQ]
    ls[LS_NEXT_SEQ] += 1.0
    ls[LS_SENT] += 1.0
    if lp[LP_LOSS] > 0.0:
        lost = pool[int(pos[POOL_NEXT])] < lp[LP_LOSS]
        pos[POOL_NEXT] += 1.0
        if lost:
            ls[LS_LOST] += 1.0
            return
    jitter = 0.0
    if lp[LP_JITTER] > 0.0:
        jitter = pool[int(pos[POOL_NEXT])] * lp[LP_JITTER]
        pos[POOL_NEXT] += 1.0
    n = int(ls[LS_COUNT])
    queue[n, Q_ARRIVAL] = t_s + lp[LP_DELAY] + jitter
    queue[n, Q_SEQ] = seq
    queue[n, Q_V1] = v1
    queue[n, Q_V2] = v2
    ls[LS_COUNT] = n + 1


@njit(cache=True)
def kernel_deliver(
    queue: np.ndarray, ls: np.ndarray, tick: float, dt: float, out: np.ndarray
) -> bool:  # pragma: no cover - compiled; exercised through TeleopLoop
    """Deliver the packets that have arrived by `tick` (a packet arriving at tick K acts
    from K + 1); the newest by send order wins. True if `out` got a new value."""
    n = int(ls[LS_COUNT])
    best = -1.0
    i = 0
    while i < n:
        if math.ceil(queue[i, Q_ARRIVAL] / dt - 1e-9) <= tick:
            if queue[i, Q_SEQ] > ls[LS_NEWEST] and queue[i, Q_SEQ] > best:
                best = queue[i, Q_SEQ]
                out[PK_V1], out[PK_V2] = queue[i, Q_V1], queue[i, Q_V2]
            # remove: move the last row here
            n -= 1
            queue[i, Q_ARRIVAL], queue[i, Q_SEQ], queue[i, Q_V1], queue[i, Q_V2] = (
                queue[n, Q_ARRIVAL],
                queue[n, Q_SEQ],
                queue[n, Q_V1],
                queue[n, Q_V2],
            )
        else:
            i += 1
    ls[LS_COUNT] = n
    if best >= 0.0:
        ls[LS_NEWEST] = best
        ls[LS_DELIVERED] += 1.0
        return True
    return False


NO_LINKS = (
    np.zeros((1, QUEUE_WIDTH)),
    np.zeros(LINK_STATE_SIZE),
    np.zeros(LINK_PARAM_SIZE),
    np.zeros((1, QUEUE_WIDTH)),
    np.zeros(LINK_STATE_SIZE),
    np.zeros(LINK_PARAM_SIZE),
    np.zeros(1),
    np.zeros(1),
)
"""The kernel's link arrays when the loop runs its links in Python (same types)."""
NO_PACKETS = np.zeros((0, SCHEDULE_WIDTH))


def kernel_links(to_master: LinkParams, to_follower: LinkParams) -> tuple:
    """Queues, states and parameters of both link directions for the kernel, and an empty
    pool of uniform draws with its position (`layout.LK_*`); the caller fills the pool
    from the links' generator, in `Link.send`'s order."""

    def state() -> np.ndarray:
        ls = np.zeros(LINK_STATE_SIZE)
        ls[LS_NEWEST] = -1.0
        return ls

    return (
        np.zeros((QUEUE_ROWS, QUEUE_WIDTH)),
        state(),
        link_vector(to_master),
        np.zeros((QUEUE_ROWS, QUEUE_WIDTH)),
        state(),
        link_vector(to_follower),
        np.zeros(0),
        np.zeros(1),
    )


def packet_schedule(
    to_master: Link[float],
    to_follower: Link[tuple[float, float]],
    k: int,
    nxt: int,
    dt_s: float,
    buffer: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The packets arriving during ticks k..nxt-1, as the kernel's schedule (`layout.SCH_*`
    rows in `buffer`, grown if needed); returns (schedule, buffer).

    A packet arriving at tick K acts from the tick after it, as if received at K.
    """
    last = (nxt - 1) * dt_s
    if to_master.next_arrival_s() > last and to_follower.next_arrival_s() > last:
        return NO_PACKETS, buffer
    rows = []
    for arrival, force in to_master.deliver_until(last):
        j = max(math.ceil(arrival / dt_s - 1e-9) - k, 0)
        rows.append((j, PACKET_FORCE, force, 0.0))
    for arrival, (speed, rotation) in to_follower.deliver_until(last):
        j = max(math.ceil(arrival / dt_s - 1e-9) - k, 0)
        rows.append((j, PACKET_COMMAND, speed, rotation))
    if len(rows) > len(buffer):
        buffer = np.zeros((2 * len(rows), SCHEDULE_WIDTH))
    rows.sort(key=lambda row: row[SCH_TICK])
    schedule = buffer[: len(rows)]
    for i, row in enumerate(rows):
        schedule[i] = row
    return schedule, buffer
