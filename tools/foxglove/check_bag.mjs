// Decode every message of MCAP files the way Foxglove does, with Foxglove's own libraries:
// @mcap/core reads the records (CRCs checked), @foxglove/rosmsg parses each `ros2msg`
// schema with `ros2: true` (dependency names matched exactly), @foxglove/ros2idl-parser
// each `ros2idl` one, and
// @foxglove/rosmsg2-serialization's MessageReader decodes each message's CDR.
//
// Usage: node check_bag.mjs [--messages] FILE.mcap [FILE.mcap ...]
//
// Prints one JSON document on stdout: per file, per channel, the topic, schema name, the
// number of messages, how many decoded, the first parse or decode error, and with
// --messages the decoded messages themselves (int64 as strings beyond 2^53, NaN and
// infinities as strings, byte arrays as lists).  Exit status: 0 when every channel's
// schema parsed and every message decoded, 1 otherwise, 2 on bad usage or an unreadable
// file.

import { readFileSync } from "node:fs";
import { createRequire } from "node:module";

import { McapStreamReader } from "@mcap/core";
import { parseRos2idl } from "@foxglove/ros2idl-parser";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";

const require = createRequire(import.meta.url);
const zstd = require("@foxglove/wasm-zstd");
const lz4 = require("@foxglove/wasm-lz4");

function plain(value) {
  if (typeof value === "bigint") {
    return Number.isSafeInteger(Number(value)) ? Number(value) : value.toString();
  }
  if (typeof value === "number") {
    return Number.isFinite(value) ? value : String(value);
  }
  if (ArrayBuffer.isView(value)) {
    return Array.from(value, plain);
  }
  if (Array.isArray(value)) {
    return value.map(plain);
  }
  if (value !== null && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, plain(v)]));
  }
  return value;
}

function checkFile(path, withMessages) {
  const reader = new McapStreamReader({
    validateCrcs: true,
    decompressHandlers: {
      zstd: (data, size) => zstd.decompress(data, Number(size)),
      lz4: (data, size) => lz4.decompress(data, Number(size)),
    },
  });
  reader.append(readFileSync(path));
  const schemas = new Map();
  const channels = new Map();
  let complete = false;
  for (let record; (record = reader.nextRecord()) !== undefined; ) {
    if (record.type === "Schema") {
      schemas.set(record.id, record);
    } else if (record.type === "Channel") {
      if (channels.has(record.id)) {
        continue;
      }
      const schema = schemas.get(record.schemaId);
      const entry = {
        topic: record.topic,
        schema_name: schema?.name ?? "",
        schema_encoding: schema?.encoding ?? "",
        message_encoding: record.messageEncoding,
        messages: 0,
        decoded: 0,
        trailing_bytes: 0,
        error: "",
      };
      if (withMessages) {
        entry.decoded_messages = [];
      }
      try {
        const encoding = schema?.encoding;
        if ((encoding !== "ros2msg" && encoding !== "ros2idl") || record.messageEncoding !== "cdr") {
          throw new Error(
            `not ros2msg or ros2idl/cdr: ${encoding ?? "no schema"}/${record.messageEncoding}`,
          );
        }
        const text = new TextDecoder().decode(schema.data);
        let definitions;
        if (encoding === "ros2msg") {
          definitions = parse(text, { ros2: true });
        } else {
          definitions = parseRos2idl(text); // in the text's order: the root type first
        }
        entry.reader = new MessageReader(definitions);
      } catch (error) {
        entry.error = `schema: ${error.message}`;
      }
      channels.set(record.id, entry);
    } else if (record.type === "Message") {
      const entry = channels.get(record.channelId);
      if (entry === undefined) {
        throw new Error(`message on unknown channel ${record.channelId}`);
      }
      entry.messages += 1;
      if (entry.reader === undefined) {
        continue;
      }
      try {
        const message = entry.reader.readMessage(record.data);
        entry.decoded += 1;
        if (entry.reader.lastReadHadTrailingBytes()) {
          entry.trailing_bytes += 1;
        }
        if (withMessages) {
          entry.decoded_messages.push({ log_time: plain(record.logTime), message: plain(message) });
        }
      } catch (error) {
        if (entry.error === "") {
          entry.error = `message ${entry.messages}: ${error.message}`;
        }
      }
    } else if (record.type === "Footer") {
      complete = true;
    }
  }
  const list = [...channels.values()].map(({ reader: _reader, ...rest }) => rest);
  const ok = complete && list.every((c) => c.error === "" && c.decoded === c.messages);
  return { path, complete, ok, channels: list };
}

async function main(argv) {
  const withMessages = argv.includes("--messages");
  const files = argv.filter((a) => a !== "--messages");
  if (files.length === 0 || files.some((f) => f.startsWith("--"))) {
    process.stderr.write("usage: node check_bag.mjs [--messages] FILE.mcap [FILE.mcap ...]\n");
    return 2;
  }
  await Promise.all([zstd.isLoaded, lz4.isLoaded]);
  const results = [];
  for (const file of files) {
    try {
      results.push(checkFile(file, withMessages));
    } catch (error) {
      process.stderr.write(`check_bag: ${file}: ${error.message}\n`);
      return 2;
    }
  }
  process.stdout.write(JSON.stringify({ files: results }, null, 1) + "\n");
  return results.every((r) => r.ok) ? 0 : 1;
}

process.exitCode = await main(process.argv.slice(2));
