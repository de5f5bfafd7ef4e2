import json
from mcap.writer import Writer

frames = [json.loads(line) for line in open("example_messages.jsonl")]  # or build the dicts in Python
with open("example.mcap", "wb") as f:
    writer = Writer(f)  # zstd-compressed chunks by default
    writer.start(profile="", library="my-retargeting-script")
    writer.add_metadata("dextrain.reference", {"format_version": "1"})
    schema = open("reference_frame.schema.json", "rb").read()  # the JSON Schema above
    schema_id = writer.register_schema("dextrain.ReferenceFrame", "jsonschema", schema)
    channel_id = writer.register_channel("/dextrain/reference", "json", schema_id)
    for frame in frames:
        ns = round(frame["t"] * 1e9)
        writer.add_message(channel_id, log_time=ns, data=json.dumps(frame).encode(), publish_time=ns)
    writer.finish()
