#!/usr/bin/env python3
"""Independent reader for dextrain rollout recordings (MCAP), used by tests/record.rs.

Usage: python3 tests/read_rollout.py ROLLOUT.mcap

Reads the file with the official Python `mcap` package (pip install mcap; zstd chunks need its
`zstandard` dependency), JSON-decodes every message and, when the `jsonschema` package is importable,
validates each message against its channel's JSON schema. Every message is also checked for
completeness: each JSON object that its schema describes with `properties` must have exactly those
keys (the Foxglove schemas list no `required` fields, so this is what catches a missing field).

Prints one JSON line (the summary) on stdout and exits 0; on any problem prints the reason on stderr
and exits 1.
"""

import json
import sys

from mcap.reader import make_reader

try:
    import jsonschema
except ImportError:  # validation is skipped; the summary says so
    jsonschema = None


class Failure(Exception):
    pass


def check_complete(schema, value, path):
    """Every object described with `properties` has exactly the declared keys (recursively)."""
    if value is None or not isinstance(schema, dict):
        return
    if isinstance(value, dict):
        if "properties" in schema:
            props = schema["properties"]
            missing = sorted(k for k in props if k not in value)
            extra = sorted(k for k in value if k not in props)
            if missing or extra:
                raise Failure(f"{path}: missing keys {missing}, undeclared keys {extra}")
            for k, v in value.items():
                check_complete(props[k], v, f"{path}.{k}")
        else:
            for alt in schema.get("anyOf", []) + schema.get("oneOf", []):
                if isinstance(alt, dict) and "properties" in alt:
                    check_complete(alt, value, path)
                    break
    elif isinstance(value, list) and isinstance(schema.get("items"), dict):
        for i, v in enumerate(value):
            check_complete(schema["items"], v, f"{path}[{i}]")


def scene_counts(msg):
    """Per entity id: the number of each primitive, plus the deletion ids."""
    out = {"entities": {}, "deletions": [d["id"] for d in msg["deletions"]]}
    for e in msg["entities"]:
        out["entities"][e["id"]] = {
            "frame_id": e["frame_id"],
            **{k: len(e[k]) for k in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models")},
        }
    return out


def main(argv):
    if len(argv) != 2:
        raise Failure("usage: read_rollout.py ROLLOUT.mcap")
    path = argv[1]
    counts = {}
    schemas = {}
    validators = {}
    validated = 0
    last_log_time = {}
    last_sequence = {}
    first = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        if summary is None:
            raise Failure("no summary section")
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            topic = channel.topic
            if schema is None:
                raise Failure(f"{topic}: channel has no schema")
            if channel.message_encoding != "json":
                raise Failure(f"{topic}: message encoding {channel.message_encoding!r}")
            if schema.encoding != "jsonschema":
                raise Failure(f"{topic}: schema encoding {schema.encoding!r}")
            schemas[topic] = {
                "name": schema.name,
                "encoding": schema.encoding,
                "message_encoding": channel.message_encoding,
            }
            if schema.id not in validators:
                schema_json = json.loads(schema.data)
                if schema_json.get("title") != schema.name:
                    raise Failure(f"{topic}: schema title {schema_json.get('title')!r} != name {schema.name!r}")
                validator = None
                if jsonschema is not None:
                    cls = jsonschema.validators.validator_for(schema_json)
                    cls.check_schema(schema_json)
                    validator = cls(schema_json)
                validators[schema.id] = (schema_json, validator)
            schema_json, validator = validators[schema.id]

            try:
                msg = json.loads(message.data)
            except ValueError as e:
                raise Failure(f"{topic} seq {message.sequence}: not JSON: {e}")
            if validator is not None:
                errors = sorted(validator.iter_errors(msg), key=lambda e: list(e.path))
                if errors:
                    e = errors[0]
                    raise Failure(f"{topic} seq {message.sequence}: {list(e.path)}: {e.message}")
                validated += 1
            check_complete(schema_json, msg, f"{topic}[{message.sequence}]")

            if message.log_time != message.publish_time:
                raise Failure(f"{topic} seq {message.sequence}: log_time != publish_time")
            if topic in last_log_time and message.log_time < last_log_time[topic]:
                raise Failure(f"{topic}: log time decreases at seq {message.sequence}")
            if topic in last_sequence and message.sequence <= last_sequence[topic]:
                raise Failure(f"{topic}: sequence does not increase at {message.sequence}")
            last_log_time[topic] = message.log_time
            last_sequence[topic] = message.sequence
            counts[topic] = counts.get(topic, 0) + 1
            if topic not in first:
                first[topic] = (message.log_time, msg)

        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}

    stats = {}
    if summary.statistics is not None:
        for cid, n in summary.statistics.channel_message_counts.items():
            stats[summary.channels[cid].topic] = n

    out = {
        "ok": True,
        "profile": header.profile,
        "validated": jsonschema is not None,
        "validated_messages": validated,
        "counts": counts,
        "summary_counts": stats,
        "schemas": schemas,
        "summary_schemas": sorted(s.name for s in summary.schemas.values()),
        "metadata_names": sorted(metadata),
        "metadata": metadata,
        "first_log_time": {t: v[0] for t, v in first.items()},
        "last_log_time": last_log_time,
    }
    if "/dextrain/hand_state" in first:
        hs = first["/dextrain/hand_state"][1]
        out["first_hand_state_position"] = hs["position"]
        out["first_hand_state_joint_names"] = hs["joint_names"]
    if "/dextrain/poses" in first:
        out["first_object_pose"] = first["/dextrain/poses"][1]["object"]
    if "/dextrain/contacts" in first:
        out["first_contacts"] = first["/dextrain/contacts"][1]["contacts"]
    if "/tf" in first:
        out["first_tf_children"] = [t["child_frame_id"] for t in first["/tf"][1]["transforms"]]
    if "/scene" in first:
        out["first_scene"] = scene_counts(first["/scene"][1])
    print(json.dumps(out, sort_keys=True))


if __name__ == "__main__":
    try:
        main(sys.argv)
    except Failure as e:
        print(f"read_rollout.py: {e}", file=sys.stderr)
        sys.exit(1)
