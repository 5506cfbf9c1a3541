"""A policy server speaking openpi's websocket protocol that replays recorded actions.

Started by eval's tests (eval/tests/remote.rs) with `websockets` and `msgpack` from PyPI; no numpy:
arrays are packed as openpi_client's msgpack_numpy packs them. Each request names its episode
(`libero_mem/episode`, "<task>@<seed>") and step (`libero_mem/step`); the reply is the next H
recorded actions of that episode from that step (fewer at its end, the last one repeated to H).

    python replay_server.py ACTIONS.json [--horizon 8]
    python replay_server.py --zeros [--horizon 8] [--fail close|shape|nan --fail-after N]

ACTIONS.json maps episode ids to lists of 7-D actions; with --zeros every reply is a chunk of
zero actions (a trivial server, to measure the protocol's cost: scripts/bench_remote.sh). Prints `port N` once listening on a free
port of 127.0.0.1, then serves until killed.
"""

import argparse
import json
import struct
import sys

import msgpack
from websockets.sync.server import serve


def ndarray_f32(rows):
    flat = [v for row in rows for v in row]
    return {
        b"__ndarray__": True,
        b"data": struct.pack("<%df" % len(flat), *flat),
        b"dtype": "<f4",
        b"shape": [len(rows), len(rows[0])],
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("actions", nargs="?")
    ap.add_argument("--horizon", type=int, default=8)
    ap.add_argument("--zeros", action="store_true")
    # Misbehave after this many good replies (counted over all connections): close the
    # connection, reply with actions of shape [H, 5], or with a NaN in the chunk.
    ap.add_argument("--fail", choices=["close", "shape", "nan"])
    ap.add_argument("--fail-after", type=int, default=0)
    args = ap.parse_args()
    episodes = {}
    if args.actions:
        with open(args.actions) as f:
            episodes = json.load(f)
    zeros = ndarray_f32([[0.0] * 7] * args.horizon)
    replies = [0]

    def handler(ws):
        ws.send(msgpack.packb({"server": "replay", "episodes": len(episodes)}))
        for message in ws:
            obs = msgpack.unpackb(message)
            replies[0] += 1
            if args.fail and replies[0] > args.fail_after:
                if args.fail == "close":
                    ws.close()
                    return
                if args.fail == "shape":
                    ws.send(msgpack.packb({"actions": ndarray_f32([[0.0] * 5] * args.horizon)}))
                    continue
                rows = [[0.0] * 7 for _ in range(args.horizon)]
                rows[1][3] = float("nan")
                ws.send(msgpack.packb({"actions": ndarray_f32(rows)}))
                continue
            if args.zeros:
                ws.send(msgpack.packb({"actions": zeros}))
                continue
            episode = obs.get("libero_mem/episode")
            step = obs.get("libero_mem/step")
            if episode not in episodes:
                ws.send("no recorded episode %r" % (episode,))
                ws.close()
                return
            subgoal = obs.get("libero_mem/subgoal", "")
            if not isinstance(subgoal, str):
                ws.send("libero_mem/subgoal is not text: %r" % (subgoal,))
                ws.close()
                return
            if "observation/image" not in obs or "observation/state" not in obs:
                ws.send("missing openpi LIBERO keys: %r" % sorted(obs))
                ws.close()
                return
            actions = episodes[episode]
            rows = actions[step : step + args.horizon] or [actions[-1]]
            rows = rows + [rows[-1]] * (args.horizon - len(rows))
            ws.send(msgpack.packb({"actions": ndarray_f32(rows)}))

    with serve(handler, "127.0.0.1", 0, compression=None, max_size=None) as server:
        print("port %d" % server.socket.getsockname()[1], flush=True)
        server.serve_forever()


if __name__ == "__main__":
    sys.exit(main())
