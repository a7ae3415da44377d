// Independent reader check of pushstep's MCAP files (test only; run by the
// cmocka tests in tests/test_e2e_recorder.c). Uses Foxglove's own libraries:
// @mcap/core (stream and indexed readers), @mcap/support (the zstd and lz4
// decompression Foxglove uses), @foxglove/rosmsg and
// @foxglove/rosmsg2-serialization (the ros2msg parser and CDR reader/writer
// Foxglove decodes messages with).
//
//   node check.mjs FILE            read FILE whole: prints one JSON object
//   node check.mjs FILE --cuts N   also cut FILE at N places (chunk ends,
//                                  one byte on, inside chunks, inside the
//                                  summary) and read each prefix
//
// Output (stdout, JSON): complete (closed with footer), schemas, channels
// (topic, schema name, encodings, messages counted by the stream reader and
// by the indexed reader, the Statistics count), per-message checks (every
// message decoded from the file's own schema, its tick/t_ns fields equal to
// the log time, and re-encoded by Foxglove's CDR writer to the very same
// bytes), metadata, and for --cuts the messages read from each prefix
// beside those of the chunks that end before the cut.
// Exit status: 0 when read; 1 on any error (message on stderr).
import { readFileSync } from "node:fs";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import { parse } from "@foxglove/rosmsg";
import { MessageReader, MessageWriter } from "@foxglove/rosmsg2-serialization";

const path = process.argv[2];
const cutsArg = process.argv.indexOf("--cuts");
const nCuts = cutsArg > 0 ? Number(process.argv[cutsArg + 1]) : 0;
const data = new Uint8Array(readFileSync(path));
const decompressHandlers = await loadDecompressHandlers();

function bigToJson(_k, v) {
  return typeof v === "bigint" ? Number(v) : v;
}

// Linear read of bytes: records in order, messages counted per channel and
// per chunk (the messages following each Chunk record are that chunk's).
function streamRead(bytes, collect) {
  const reader = new McapStreamReader({ includeChunks: true, decompressHandlers, validateCrcs: true });
  reader.append(bytes);
  const out = { messages: 0, byChannel: new Map(), chunkCounts: [], schemas: new Map(),
                channels: new Map(), metadata: [], done: false };
  for (let rec; (rec = reader.nextRecord()); ) {
    switch (rec.type) {
      case "Chunk":
        out.chunkCounts.push(0);
        break;
      case "Schema":
        out.schemas.set(rec.id, rec);
        break;
      case "Channel":
        out.channels.set(rec.id, rec);
        break;
      case "Message":
        out.messages++;
        out.byChannel.set(rec.channelId, (out.byChannel.get(rec.channelId) ?? 0) + 1);
        if (out.chunkCounts.length > 0) out.chunkCounts[out.chunkCounts.length - 1]++;
        if (collect) collect(rec, out);
        break;
      case "Metadata":
        out.metadata.push({ name: rec.name, metadata: Object.fromEntries(rec.metadata) });
        break;
      default:
        break;
    }
  }
  out.done = reader.done();
  out.bytesRemaining = reader.bytesRemaining();
  return out;
}

// Decode with the file's own schema, check the stamp, re-encode.
const codecs = new Map();
const checks = { decoded: 0, stampMismatch: 0, reencodeMismatch: 0, firstProblem: null };
function checkMessage(msg, st) {
  const ch = st.channels.get(msg.channelId);
  let codec = codecs.get(msg.channelId);
  if (!codec) {
    const schema = st.schemas.get(ch.schemaId);
    const text = new TextDecoder().decode(schema.data);
    const defs = parse(text, { ros2: true });
    codec = { reader: new MessageReader(defs), writer: new MessageWriter(defs) };
    codecs.set(msg.channelId, codec);
  }
  const value = codec.reader.readMessage(msg.data);
  checks.decoded++;
  if (BigInt(value.t_ns) !== msg.logTime || (value.tick === undefined)) {
    checks.stampMismatch++;
    checks.firstProblem ??= `${ch.topic}: t_ns ${value.t_ns} vs log time ${msg.logTime}`;
  }
  const again = codec.writer.writeMessage(value);
  const same = again.length === msg.data.length && again.every((b, i) => b === msg.data[i]);
  if (!same) {
    checks.reencodeMismatch++;
    checks.firstProblem ??= `${ch.topic}: re-encoded ${again.length} bytes differ from the ${msg.data.length} in the file`;
  }
}

const full = streamRead(data, checkMessage);
const result = {
  file: path,
  bytes: data.length,
  complete: full.done,
  messages: full.messages,
  chunks: full.chunkCounts.length,
  schemas: [...full.schemas.values()].map((s) => ({ id: s.id, name: s.name, encoding: s.encoding })),
  channels: [],
  checks,
  metadata: full.metadata,
};

let indexed = null;
if (full.done) {
  const readable = {
    size: async () => BigInt(data.length),
    read: async (offset, size) => data.subarray(Number(offset), Number(offset + size)),
  };
  indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const counts = new Map();
  for await (const m of indexed.readMessages({ validateCrcs: true })) {
    counts.set(m.channelId, (counts.get(m.channelId) ?? 0) + 1);
  }
  result.statistics = {
    messageCount: Number(indexed.statistics?.messageCount ?? -1),
    schemaCount: indexed.statistics?.schemaCount ?? -1,
    channelCount: indexed.statistics?.channelCount ?? -1,
    chunkCount: indexed.statistics?.chunkCount ?? -1,
    metadataCount: indexed.statistics?.metadataCount ?? -1,
  };
  result.chunkIndexes = indexed.chunkIndexes.length;
  result.indexedChannels = indexed.channelsById.size;
  result.indexedSchemas = indexed.schemasById.size;
  for (const [id, ch] of full.channels) {
    result.channels.push({
      id, topic: ch.topic, schema: full.schemas.get(ch.schemaId)?.name, messageEncoding: ch.messageEncoding,
      schemaEncoding: full.schemas.get(ch.schemaId)?.encoding,
      messages: full.byChannel.get(id) ?? 0,
      indexedMessages: counts.get(id) ?? 0,
      statisticsMessages: Number(indexed.statistics?.channelMessageCounts.get(id) ?? -1n),
    });
  }
} else {
  for (const [id, ch] of full.channels) {
    result.channels.push({ id, topic: ch.topic, schema: full.schemas.get(ch.schemaId)?.name,
      messageEncoding: ch.messageEncoding, messages: full.byChannel.get(id) ?? 0 });
  }
}

// Cuts: where the chunks end (from the chunk index of the closed file).
if (nCuts > 0) {
  if (!indexed) throw new Error("--cuts needs a closed file (with its chunk index)");
  const chunks = [...indexed.chunkIndexes].sort((a, b) => Number(a.chunkStartOffset - b.chunkStartOffset));
  const ends = chunks.map((c) => Number(c.chunkStartOffset + c.chunkLength));
  const cuts = new Set();
  const dataEnd = Number(indexed.dataEndOffset);
  for (let k = 0; k < nCuts && k < chunks.length; k++) {
    const i = Math.floor((k * chunks.length) / nCuts); // N chunks spread over the file
    const start = Number(chunks[i].chunkStartOffset);
    cuts.add(ends[i]);                                        // exactly at a chunk's end
    cuts.add(start + 1);                                      // one byte into a chunk
    cuts.add(start + Math.floor(Number(chunks[i].chunkLength) / 2)); // half a chunk
  }
  cuts.add(dataEnd + 5);                                      // inside the summary
  cuts.add(data.length - 3);                                  // inside the closing magic
  result.cuts = [];
  for (const cut of [...cuts].sort((a, b) => a - b)) {
    let expected = 0;
    for (let i = 0; i < chunks.length; i++) if (ends[i] <= cut) expected += full.chunkCounts[i];
    let got = -1, error = null, done = false;
    try {
      const part = streamRead(data.subarray(0, cut), null);
      got = part.messages;
      done = part.done;
    } catch (e) {
      error = String(e.message ?? e);
    }
    result.cuts.push({ cut, expected, got, done, error });
  }
}

process.stdout.write(JSON.stringify(result, bigToJson, 1) + "\n");
