#!/usr/bin/env python3
"""Validate episode files with the reference MCAP reader (PyPI `mcap`, `mcap-protobuf-support`,
`zstandard`).

Usage: validate_mcap.py PATH...   (files or directories of *.mcap)

Checks, per file: chunk/data CRCs (validate_crcs=True, plus a full non-seeking linear read),
the summary (statistics, chunk indexes), the `episode` metadata record, that the Foxglove
image channels decode with their embedded protobuf FileDescriptorSet, that JSON channels parse,
and that every channel has one message per step with sequence = step and
log_time = round(step * 1e9 / fps). Exit status 0 if every file passes, 1 otherwise.
"""

import json
import sys
from collections import defaultdict
from pathlib import Path

from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader, NonSeekingReader
from mcap_protobuf.decoder import DecoderFactory


class JsonDecoderFactory(McapDecoderFactory):
    """Decodes `json` messages whose schema encoding is `jsonschema`."""

    def decoder_for(self, message_encoding, schema):
        if message_encoding == "json" and schema is not None and schema.encoding == "jsonschema":
            json.loads(schema.data)  # the schema itself must be valid JSON
            return json.loads
        return None

REQUIRED = {
    "/agentview/image": ("foxglove.CompressedImage", "protobuf"),
    "/eye_in_hand/image": ("foxglove.CompressedImage", "protobuf"),
    "/robot/state": ("lmr.State", "json"),
    "/robot/joint_state": ("lmr.JointState", "json"),
    "/robot/action": ("lmr.Action", "json"),
    "/objects": ("lmr.ObjectAnnotations", "json"),
    "/goal": ("lmr.GoalProgress", "json"),
}
OPTIONAL = {
    "/agentview/segmentation": ("foxglove.RawImage", "protobuf"),
    "/agentview/depth": ("foxglove.RawImage", "protobuf"),
}
MAGIC = {"png": b"\x89PNG", "jpeg": b"\xff\xd8"}


def check(path: Path) -> list[str]:
    errors = []
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            return ["no summary section"]
        if not summary.chunk_indexes:
            errors.append("no chunk indexes")
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        if "episode" not in meta:
            return errors + ["no `episode` metadata"]
        ep = meta["episode"]
        fps = float(ep["fps"])
        if ep.get("schema_version") not in ("libero-mem-rs/episode/1", "libero-mem-rs/episode/2", "libero-mem-rs/episode/3"):
            errors.append(f"schema_version {ep.get('schema_version')!r}")
        topics = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas[ch.schema_id]
            topics[ch.topic] = (schema.name, ch.message_encoding)
        for t, want in REQUIRED.items():
            if topics.get(t) != want:
                errors.append(f"channel {t}: {topics.get(t)} != {want}")
        for t, want in OPTIONAL.items():
            if t in topics and topics[t] != want:
                errors.append(f"channel {t}: {topics[t]} != {want}")
        seqs = defaultdict(list)
        n_msgs = 0
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            n_msgs += 1
            k = message.sequence
            seqs[channel.topic].append(k)
            want_t = round(k * 1e9 / fps)
            if message.log_time != want_t:
                errors.append(f"{channel.topic} step {k}: log_time {message.log_time} != {want_t}")
            if channel.message_encoding == "json":
                body = decoded
                if body.get("step") != k:
                    errors.append(f"{channel.topic}: JSON step {body.get('step')} != sequence {k}")
            elif schema.name == "foxglove.CompressedImage":
                if decoded.format not in MAGIC or not decoded.data.startswith(MAGIC[decoded.format]):
                    errors.append(f"{channel.topic} step {k}: bad {decoded.format!r} image")
            elif schema.name == "foxglove.RawImage":
                bpp = {"16UC1": 2, "32SC1": 4, "32FC1": 4}.get(decoded.encoding)
                if bpp is None or len(decoded.data) != decoded.width * decoded.height * bpp or decoded.step != decoded.width * bpp:
                    errors.append(f"{channel.topic} step {k}: raw image {decoded.encoding} size mismatch")
        counts = {t: len(v) for t, v in seqs.items()}
        n = counts.get("/robot/state", 0)
        if n == 0:
            errors.append("no steps")
        for t, v in seqs.items():
            if sorted(v) != list(range(n)):
                errors.append(f"{t}: sequences are not 0..{n - 1}")
        stats = summary.statistics
        if stats is None or stats.message_count != n_msgs:
            errors.append(f"statistics message_count {getattr(stats, 'message_count', None)} != {n_msgs}")
    # Independent full linear read (no summary), validating every CRC again.
    with open(path, "rb") as f:
        linear = sum(1 for _ in NonSeekingReader(f, validate_crcs=True).iter_messages())
    if linear != n_msgs:
        errors.append(f"linear read found {linear} messages, indexed read {n_msgs}")
    return errors


def main(argv: list[str]) -> int:
    files = []
    for a in argv:
        p = Path(a)
        files.extend(sorted(p.glob("*.mcap")) if p.is_dir() else [p])
    if not files:
        print("validate_mcap: no .mcap files given", file=sys.stderr)
        return 1
    bad = 0
    for p in files:
        try:
            errs = check(p)
        except Exception as e:  # the reference reader rejected the file
            errs = [f"{type(e).__name__}: {e}"]
        if errs:
            bad += 1
            print(f"FAIL {p}")
            for e in errs[:20]:
                print(f"  {e}")
        else:
            print(f"ok   {p}")
    print(f"validate_mcap: {len(files) - bad}/{len(files)} files pass the reference mcap reader")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
