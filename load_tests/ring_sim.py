"""HAProxy 2.6's consistent hash ring, simulated: which node each session's route key goes to, how
many keys move when a node joins or leaves, and how unevenly keys spread, for 2 to 200 nodes.

    python -m load_tests.ring_sim [--keys 100000] [--nodes 2,3,...,200] [--weights 1,16,256]
        [--balance-factor 125] [--json FILE]

The model is HAProxy's own algorithm (src/lb_chash.c, src/backend.c, src/hash.c of 2.x), checked
against the running balancer by tests/deploy (the same keys land on the same nodes):
- a server of weight w has w * 16 points on a 32-bit ring (BE_WEIGHT_SCALE = 16), point j at
  full_hash(server_id * 4096 + j) (SRV_EWGHT_RANGE = 256 * 16), full_hash being Bob Jenkins'
  32-bit integer avalanche times 3221225473; a server's points depend on its id and weight alone;
- `balance hdr(x)` with `hash-type consistent` and no hash function named hashes the header's value
  with sdbm, then full_hash ("sdbm and avalanche");
- a key goes to the server of the nearest point, before or after it on the ring (the one before on
  a tie), not to the next point as in textbook consistent hashing;
- `hash-balance-factor F` (bounded loads, Mirrokni et al.) skips to the following points while the
  chosen server already serves ceil((served + 1) * F / 100) / servers streams.

Reported per node count N and weight: `moved_on_join` (the keys whose node changes when node N+1
joins; ideal 1/(N+1)), `moved_to_others_on_join` (of those, the ones that went anywhere but the new
node: 0 for a consistent hash), `moved_on_leave` (when the node holding the most keys leaves; its
share), `max_over_mean` (the busiest node's keys over the mean; 1 is perfectly even; with few keys
per node it measures the keys' own scatter too) and `max_arc_over_mean` (the same for the ring's
arcs: the spread of infinitely many keys). With
--balance-factor, for a few N: the same spread of long-lived streams with bounded loads, and the
fraction of sessions that bounded loads sent to a node other than their key's (each of which would
be restored from its checkpoint there).
"""

from __future__ import annotations

import argparse
import time
import uuid
from pathlib import Path

import numpy as np

from load_tests.report import emit

BE_WEIGHT_SCALE = 16  # ring points per unit of weight (include/haproxy/backend-t.h)
SRV_EWGHT_RANGE = 256 * BE_WEIGHT_SCALE  # spacing of server ids' point numbers (include/haproxy/server-t.h)
DEFAULT_NODES = (2, 3, 4, 5, 8, 10, 16, 20, 32, 50, 64, 100, 128, 200)
M32 = np.uint64(0xFFFFFFFF)


def full_hash(a: np.ndarray) -> np.ndarray:
    """HAProxy's full_hash: Bob Jenkins' 32-bit full avalanche, then a multiplication by a prime,
    on (n,) integers; (n,) uint32."""
    a = np.asarray(a, dtype=np.uint64) & M32
    a = ((a + 0x7ED55D16) + (a << np.uint64(12))) & M32
    a = ((a ^ 0xC761C23C) ^ (a >> np.uint64(19))) & M32
    a = ((a + 0x165667B1) + (a << np.uint64(5))) & M32
    a = ((a + 0xD3A2646C) ^ (a << np.uint64(9))) & M32
    a = ((a + 0xFD7046C5) + (a << np.uint64(3))) & M32
    a = ((a ^ 0xB55A4F09) ^ (a >> np.uint64(16))) & M32
    return ((a * np.uint64(3221225473)) & M32).astype(np.uint32)  # spread over the tree (a prime near 3/4 of 2^32)


def key_hashes(keys: list[str]) -> np.ndarray:
    """full_hash(sdbm(key)) of each key, as `hash-type consistent` hashes a header's value; keys of
    one length (uuid4 hex, as the SDKs make them) are hashed column by column. (n,) uint32."""
    raw = np.frombuffer("".join(keys).encode(), dtype=np.uint8).reshape(len(keys), -1).astype(np.uint64)
    h = np.zeros(len(keys), dtype=np.uint64)
    for c in raw.T:  # sdbm: hash = c + (hash << 6) + (hash << 16) - hash
        h = (c + (h << np.uint64(6)) + (h << np.uint64(16)) - h) & M32
    return full_hash(h)


class Ring:
    """The active servers' points, sorted: `servers` maps server id to weight."""

    def __init__(self, servers: dict[int, int]):
        ids = np.concatenate([np.full(w * BE_WEIGHT_SCALE, sid) for sid, w in servers.items()])
        numbers = np.concatenate([sid * SRV_EWGHT_RANGE + np.arange(w * BE_WEIGHT_SCALE) for sid, w in servers.items()])
        points = full_hash(numbers)
        order = np.argsort(points, kind="stable")
        self.points, self.owners = points[order].astype(np.int64), ids[order]

    def nearest(self, hashes: np.ndarray) -> np.ndarray:
        """The index in `points` of the point nearest each hash (chash_get_server_hash)."""
        h = hashes.astype(np.int64)
        n = len(self.points)
        after = np.searchsorted(self.points, h, side="left") % n  # eb32_lookup_ge, wrapping to the first
        before = (after - 1) % n  # eb32_prev, wrapping to the last
        dp = (h - self.points[before]) % (1 << 32)
        dn = (self.points[after] - h) % (1 << 32)
        return np.where(dp <= dn, before, after)

    def arc_spread(self) -> float:
        """The largest server's share of the ring over the mean share: the key spread with
        infinitely many keys (a point owns the half-gaps on both sides of it)."""
        gaps = np.diff(self.points, append=self.points[0] + (1 << 32))
        arcs = (gaps + np.roll(gaps, 1)) / 2.0
        shares = np.bincount(self.owners, weights=arcs)
        shares = shares[np.unique(self.owners)]
        return float(shares.max() / shares.mean())

    def owner(self, hashes: np.ndarray) -> np.ndarray:
        """The server id each hash goes to, with no load bound. (n,) int."""
        return self.owners[self.nearest(hashes)]

    def bounded(self, hashes: np.ndarray, factor_pct: int) -> np.ndarray:
        """Server ids of streams opened one after another and all kept open, with
        `hash-balance-factor factor_pct` (chash_server_is_eligible, equal weights): the nearest
        point's server is skipped for the next points' while it serves its slots of
        ceil((served + 1) * factor / 100), shared out by weight."""
        servers = list(np.unique(self.owners))
        rank = {int(s): i for i, s in enumerate(servers)}  # cumulative_weight follows the servers' order
        weight = int(np.sum(self.owners == servers[0]))  # effective weight: one per point
        total = weight * len(servers)
        served = np.zeros(len(servers), dtype=np.int64)
        out = np.empty(len(hashes), dtype=np.int64)
        n = len(self.points)

        def eligible(server: int, in_flight: int) -> bool:
            slots_total = (in_flight * factor_pct + 99) // 100
            per_weight, remainder = divmod(slots_total, total)
            cumulative = rank[server] * weight
            slots = weight * per_weight + ((cumulative + weight) * remainder) // total - (cumulative * remainder) // total
            return served[rank[server]] < max(slots, 1)

        for k, at in enumerate(self.nearest(hashes)):
            while not eligible(int(self.owners[at]), k + 1):
                at = (at + 1) % n
            out[k] = self.owners[at]
            served[rank[int(out[k])]] += 1
        return out


def spread(owners: np.ndarray) -> float:
    """The busiest server's keys over the mean."""
    counts = np.unique(owners, return_counts=True)[1]
    return float(counts.max() / counts.mean())


def simulate(n_keys: int, node_counts, weights, balance_factor: int, seed: int = 1) -> dict:
    rng = np.random.default_rng(seed)
    keys = [uuid.UUID(bytes=bytes(rng.integers(0, 256, 16, dtype=np.uint8)), version=4).hex for _ in range(n_keys)]
    hashes = key_hashes(keys)
    rows = []
    for weight in weights:
        for n in node_counts:
            ring = Ring({sid: weight for sid in range(1, n + 1)})
            before = ring.owner(hashes)
            joined = Ring({sid: weight for sid in range(1, n + 2)}).owner(hashes)
            moved = before != joined
            busiest = int(np.bincount(before).argmax())
            left = Ring({sid: weight for sid in range(1, n + 1) if sid != busiest}).owner(hashes)
            rows.append(
                {
                    "nodes": n,
                    "weight": weight,
                    "points_per_node": weight * BE_WEIGHT_SCALE,
                    "moved_on_join": round(float(moved.mean()), 4),
                    "ideal_on_join": round(1 / (n + 1), 4),
                    "moved_to_others_on_join": int((moved & (joined != n + 1)).sum()),
                    "moved_on_leave": round(float((before != left).mean()), 4),
                    "ideal_on_leave": round(1 / n, 4),
                    "max_over_mean": round(spread(before), 3),
                    "max_arc_over_mean": round(ring.arc_spread(), 3),
                }
            )
    bounded = []
    for weight in sorted({min(weights), max(weights)}) if balance_factor else ():
        for n in (n for n in node_counts if n in (10, 50, 100)):
            ring = Ring({sid: weight for sid in range(1, n + 1)})
            placed = ring.bounded(hashes, balance_factor)
            bounded.append(
                {
                    "nodes": n,
                    "weight": weight,
                    "balance_factor_pct": balance_factor,
                    "max_over_mean": round(spread(placed), 3),
                    "max_over_mean_unbounded": round(spread(ring.owner(hashes)), 3),
                    "off_their_key_node": round(float((placed != ring.owner(hashes)).mean()), 4),
                }
            )
    return {
        "keys": n_keys,
        "key_kind": "uuid4 hex (32 characters), as the SDKs make route keys",
        "model": "HAProxy 2.x hash-type consistent, sdbm + avalanche, weight * 16 points per server",
        "rows": rows,
        "bounded_loads": bounded,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keys", type=int, default=100_000, help="route keys (sessions) placed")
    parser.add_argument("--nodes", default=",".join(map(str, DEFAULT_NODES)), help="node counts, comma-separated")
    parser.add_argument(
        "--weights", default="1,16,256", help="server weights, comma-separated (1 is HAProxy's default; cluster.py uses 256)"
    )
    parser.add_argument(
        "--balance-factor",
        type=int,
        default=125,
        help="hash-balance-factor to simulate for 10, 50 and 100 nodes, percent (0: none)",
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    result = simulate(
        args.keys,
        [int(n) for n in args.nodes.split(",")],
        [int(w) for w in args.weights.split(",")],
        args.balance_factor,
        args.seed,
    )
    result["wall_s"] = round(time.perf_counter() - start, 1)
    emit(result, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
