"""Reads MCAP recordings with the reference Python reader (`pip install mcap`), as a lab's own tools would, and prints
one JSON object per file: how many messages it reads before it stops and why, the log time of the last one, the
summary if the file has one, and (with --decode) whether every message decodes against the schema stored in the
file (protobuf through mcap-protobuf-support, JSON against its JSON Schema).

Usage: python mcap_check.py [--decode] FILE...
"""

import json
import sys

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader


def summary_of(path):
    """The summary section, read as a seeking reader (Foxglove, `mcap info`) does; None without a footer."""
    with open(path, "rb") as stream:
        try:
            summary = make_reader(stream).get_summary()
        except (McapError, EOFError, ValueError, OSError) as error:
            return None, f"{type(error).__name__}: {error}"
        if summary is None or summary.statistics is None:
            return None, "no summary section"
        return {
            "message_count": summary.statistics.message_count,
            "chunk_count": summary.statistics.chunk_count,
            "chunk_indexes": len(summary.chunk_indexes),
            "channels": sorted(c.topic for c in summary.channels.values()),
            "metadata_indexes": len(summary.metadata_indexes),
        }, None


def decoder_for(schema, channel, decoders, decode_protobuf):
    key = channel.id
    if key not in decoders:
        if channel.message_encoding == "protobuf":
            decoders[key] = decode_protobuf.decoder_for("protobuf", schema)
        elif channel.message_encoding == "json":
            import jsonschema

            validator = jsonschema.Draft202012Validator(json.loads(schema.data)) if schema else None

            def decode_json(data, validator=validator):
                value = json.loads(data)
                if validator is not None:
                    validator.validate(value)
                return value

            decoders[key] = decode_json
        else:
            decoders[key] = None
    return decoders[key]


def read_linearly(path, decode):
    """Every message in file order with the library's streaming reader, which needs no footer: what a cut file
    offers. Stops at the first record that is cut off or damaged."""
    result = {"messages": 0, "stopped_by": None, "last_log_time": None, "topics": {}, "decoded": 0}
    decoders = {}
    decode_protobuf = None
    if decode:
        from mcap_protobuf.decoder import DecoderFactory

        decode_protobuf = DecoderFactory()
    with open(path, "rb") as stream:
        try:
            for schema, channel, message in NonSeekingReader(stream, validate_crcs=True).iter_messages(log_time_order=False):
                result["messages"] += 1
                result["last_log_time"] = message.log_time
                result["topics"][channel.topic] = result["topics"].get(channel.topic, 0) + 1
                if decode:
                    decoder = decoder_for(schema, channel, decoders, decode_protobuf)
                    if decoder is None:
                        raise ValueError(f"no decoder for {channel.message_encoding} on {channel.topic}")
                    decoded = decoder(message.data)
                    if decoded is None:
                        raise ValueError(f"message on {channel.topic} does not decode")
                    result["decoded"] += 1
        except Exception as error:  # the reader's own exceptions vary by what was cut; keep what was read
            result["stopped_by"] = f"{type(error).__name__}: {error}"
    return result


def indexed_count(path):
    """Messages read through the summary's chunk indexes (a seeking reader); None when the file has no summary."""
    with open(path, "rb") as stream:
        try:
            return sum(1 for _ in make_reader(stream, validate_crcs=True).iter_messages(log_time_order=False))
        except Exception as error:
            return f"{type(error).__name__}: {error}"


def main(argv):
    decode = "--decode" in argv
    for path in [a for a in argv if a != "--decode"]:
        report = {"path": path}
        report.update(read_linearly(path, decode))
        report["summary"], report["summary_error"] = summary_of(path)
        report["indexed_messages"] = indexed_count(path) if report["summary"] else None
        print(json.dumps(report), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
