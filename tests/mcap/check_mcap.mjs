// Reads an MCAP file written by fovea with the format's reference library,
// @mcap/core: McapIndexedReader (the summary, chunk indexes, seeking) and
// McapStreamReader (sequential, CRCs checked), zstd through @mcap/support's
// loadDecompressHandlers. Fails (exit 1) on any difference.
//
//   node check_mcap.mjs --writer PROGRAM --workdir DIR   fovea's Writer: runs
//        PROGRAM (tests/mcap/mcap_sample_writer.cpp) for a file and a manifest
//        of what it wrote, then compares every schema, channel and message
//   node check_mcap.mjs --fovead FOVEAD --workdir DIR [--frames N]
//        `fovead serve --record` over a short mock run: the four /fovea/
//        channels, their schemas, message counts against the statistics, and
//        the chunks channel against the frames
//        (with --operator FOVEA_OPERATOR: a second run with an operator connected, whose gaze
//        must be recorded)
//   node check_mcap.mjs --file F.mcap [--manifest M.json] a given file
//
// The packages come from toolchain/node/node_modules (bash toolchain/setup-host).
import { createRequire } from "node:module";
import { execFileSync, spawn, spawnSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const root = path.resolve(here, "..", "..");
const modules = path.join(root, "toolchain", "node", "node_modules");
if (!fs.existsSync(path.join(modules, "@mcap", "core")) || !fs.existsSync(path.join(modules, "@mcap", "support"))) {
  console.error(`check_mcap: ${modules} has no @mcap/core or @mcap/support: run bash toolchain/setup-host`);
  process.exit(1);
}
const require = createRequire(path.join(modules, "..", "package.json"));
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");

// A cross build's programs run through its emulator (FOVEA_EMULATOR, e.g. qemu-aarch64).
const emulator = (process.env.FOVEA_EMULATOR ?? "").split(" ").filter(Boolean);
function command(cmd, args) {
  return emulator.length > 0 ? [emulator[0], [...emulator.slice(1), cmd, ...args]] : [cmd, args];
}

let failures = 0;
let checks = 0;
function check(condition, what) {
  checks++;
  if (!condition) {
    failures++;
    console.error(`FAIL: ${what}`);
  }
}
const hex = (bytes) => Buffer.from(bytes.buffer, bytes.byteOffset, bytes.byteLength).toString("hex");

function args() {
  const out = {};
  const argv = process.argv.slice(2);
  for (let i = 0; i < argv.length; i += 2) out[argv[i].replace(/^--/, "")] = argv[i + 1];
  return out;
}

async function readIndexed(bytes, decompressHandlers) {
  const readable = {
    size: async () => BigInt(bytes.byteLength),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const messages = [];
  for await (const m of reader.readMessages()) messages.push(m);
  return { reader, messages };
}

function readStream(bytes, decompressHandlers) {
  const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  reader.append(bytes);
  const records = [];
  for (let r; (r = reader.nextRecord()) !== undefined; ) records.push(r);
  return { done: reader.done(), records };
}

// What both readers must agree on, and the statistics with them.
async function readBoth(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const decompressHandlers = await loadDecompressHandlers();
  const indexed = await readIndexed(bytes, decompressHandlers);
  const stream = readStream(bytes, decompressHandlers);
  const r = indexed.reader;
  check(r.statistics !== undefined, `${file}: the indexed reader found Statistics in the summary`);
  check(stream.done, `${file}: the stream reader reached the end (footer and magic)`);
  const streamMessages = stream.records.filter((x) => x.type === "Message");
  const streamSchemas = stream.records.filter((x) => x.type === "Schema");
  const streamChannels = stream.records.filter((x) => x.type === "Channel");
  check(stream.records.some((x) => x.type === "Footer"), `${file}: the stream reader read the footer`);
  check(stream.records.some((x) => x.type === "DataEnd"), `${file}: the stream reader read DataEnd`);
  const s = r.statistics ?? { messageCount: -1n, channelMessageCounts: new Map(), chunkCount: -1 };
  check(s.messageCount === BigInt(indexed.messages.length),
        `${file}: statistics.messageCount ${s.messageCount} = messages the indexed reader read ${indexed.messages.length}`);
  check(indexed.messages.length === streamMessages.length,
        `${file}: both readers read as many messages (${indexed.messages.length}, ${streamMessages.length})`);
  check(s.chunkCount === r.chunkIndexes.length, `${file}: statistics.chunkCount ${s.chunkCount} = chunk indexes ${r.chunkIndexes.length}`);
  check(s.channelCount === r.channelsById.size, `${file}: statistics.channelCount = channels in the summary`);
  check(s.schemaCount === r.schemasById.size, `${file}: statistics.schemaCount = schemas in the summary`);
  const perChannel = new Map();
  for (const m of indexed.messages) perChannel.set(m.channelId, (perChannel.get(m.channelId) ?? 0) + 1);
  for (const [id] of r.channelsById) {
    check(BigInt(perChannel.get(id) ?? 0) === (s.channelMessageCounts.get(id) ?? -1n),
          `${file}: channel ${id}: statistics count ${s.channelMessageCounts.get(id)} = messages read ${perChannel.get(id) ?? 0}`);
  }
  // The indexed reader gives log-time order; the stream reader file order. Same multiset.
  const key = (m) => `${m.channelId}/${m.sequence}/${m.logTime}/${m.publishTime}/${hex(m.data)}`;
  const a = indexed.messages.map(key).sort();
  const b = streamMessages.map(key).sort();
  check(a.length === b.length && a.every((x, i) => x === b[i]), `${file}: both readers read the same messages`);
  // Seeking: a time range in the middle gives exactly the messages in it.
  if (indexed.messages.length > 2) {
    const times = indexed.messages.map((m) => m.logTime).sort((x, y) => (x < y ? -1 : x > y ? 1 : 0));
    const startTime = times[Math.floor(times.length / 3)];
    const endTime = times[Math.floor((2 * times.length) / 3)];
    let n = 0;
    for await (const m of r.readMessages({ startTime, endTime })) {
      check(m.logTime >= startTime && m.logTime <= endTime, `${file}: a seek returned a message outside its range`);
      n++;
    }
    const expected = times.filter((t) => t >= startTime && t <= endTime).length;
    check(n === expected, `${file}: seeking to [${startTime}, ${endTime}] read ${n} messages, ${expected} are in it`);
  }
  return { indexed, stream: { messages: streamMessages, schemas: streamSchemas, channels: streamChannels } };
}

async function compareManifest(file, manifestFile) {
  const manifest = JSON.parse(fs.readFileSync(manifestFile, "utf8"));
  const { indexed, stream } = await readBoth(file);
  const r = indexed.reader;
  for (const want of manifest.schemas) {
    for (const [who, got] of [["indexed", r.schemasById.get(want.id)], ["stream", stream.schemas.find((x) => x.id === want.id)]]) {
      check(got !== undefined, `${who}: schema ${want.id} found`);
      if (!got) continue;
      check(got.name === want.name && got.encoding === want.encoding && hex(got.data) === want.data_hex,
            `${who}: schema ${want.id} (${want.name}) has the name, encoding and data written`);
    }
  }
  check(r.schemasById.size === manifest.schemas.length, `the summary has ${manifest.schemas.length} schemas`);
  for (const want of manifest.channels) {
    for (const [who, got] of [["indexed", r.channelsById.get(want.id)], ["stream", stream.channels.find((x) => x.id === want.id)]]) {
      check(got !== undefined, `${who}: channel ${want.id} found`);
      if (!got) continue;
      check(got.topic === want.topic && got.messageEncoding === want.message_encoding && got.schemaId === want.schema_id,
            `${who}: channel ${want.id} (${want.topic}) has the topic, encoding and schema written`);
      for (const [k, v] of Object.entries(want.metadata)) check(got.metadata.get(k) === v, `${who}: channel ${want.id} metadata ${k}`);
    }
  }
  check(r.channelsById.size === manifest.channels.length, `the summary has ${manifest.channels.length} channels`);
  check(stream.messages.length === manifest.messages.length,
        `the stream reader read ${stream.messages.length} messages, ${manifest.messages.length} were written`);
  manifest.messages.forEach((want, i) => {
    const got = stream.messages[i];
    if (!got) return;
    const same = got.channelId === want.channel && got.logTime === BigInt(want.log_time) &&
                 got.publishTime === BigInt(want.publish_time) && hex(got.data) === want.data_hex;
    check(same, `message ${i} (channel ${want.channel}) is read back as written`);
  });
  const counts = {};
  for (const m of manifest.messages) counts[m.channel] = (counts[m.channel] ?? 0) + 1;
  for (const c of manifest.channels) {
    check((r.statistics?.channelMessageCounts.get(c.id) ?? -1n) === BigInt(counts[c.id] ?? 0),
          `statistics: channel ${c.id} has ${counts[c.id] ?? 0} messages`);
  }
}

async function checkFovead(fovead, workdir, frames) {
  const file = path.join(workdir, "fovead-serve.mcap");
  fs.rmSync(file, { force: true });
  const run = spawnSync(...command(fovead, ["serve", "--camera", "mock:living-room,realtime=on", "--frames", String(frames),
                                    "--listen", "127.0.0.1:0", "--insecure", "--status-interval-ms", "100", "--record", file]), { encoding: "utf8", stdio: ["ignore", "pipe", "pipe"], timeout: 120000 });
  if (run.status !== 0) throw new Error(`fovead serve --record exited with ${run.status ?? run.signal}: ${run.stderr}`);
  const out = run.stdout;
  process.stdout.write(out.split("\n").filter((l) => l.includes("record") || l.includes("stopped")).join("\n") + "\n");
  const foveated = Number((/stopped after (\d+) frames foveated/.exec(out) ?? [])[1] ?? -1);
  // A frame the send stage had not taken when the next one came is dropped by
  // the ring between the stages (counted; a slow build, ASan beside other tests,
  // drops a few): it was recorded as foveated (pose, cloud) but never encoded.
  const stopLine = run.stderr.split("\n").find((l) => l.includes("info: stopped:")) ?? "";
  process.stdout.write(stopLine + "\n");
  // The recorder's producer rings are small (4 clouds); a writer thread starved
  // of CPU (ASan beside other tests) drops what finds its ring full, counted on
  // its summary line: a cloud channel short by at most that many is its drops.
  const recordingLine = run.stderr.split("\n").find((l) => /recording .*dropped: ring full/.test(l)) ?? "";
  process.stdout.write(recordingLine + "\n");
  const ringFullDrops = Number((/dropped: ring full (\d+)/.exec(recordingLine) ?? [])[1] ?? -1);
  check(ringFullDrops >= 0, `fovead's recording line counts the messages its full rings dropped: '${recordingLine}'`);
  const handoffDrops = Number((/drops capture \d+ foveation (\d+)/.exec(stopLine) ?? [])[1] ?? -1);
  check(handoffDrops >= 0, `fovead's stop line counts the frames dropped between foveation and send: '${stopLine}'`);
  const { indexed, stream } = await readBoth(file);
  const r = indexed.reader;
  const topics = new Map([...r.channelsById.values()].map((c) => [c.topic, c]));
  for (const topic of ["/fovea/chunks", "/fovea/gaze", "/fovea/camera_pose", "/fovea/status"]) {
    check(topics.has(topic), `fovead's recording has the channel ${topic}`);
    const c = topics.get(topic);
    if (c && c.schemaId !== 0) {
      const schema = r.schemasById.get(c.schemaId);
      check(schema !== undefined && schema.data.byteLength > 0, `${topic}: its schema (${schema?.name}) is embedded`);
    }
  }
  const count = (topic) => {
    const c = topics.get(topic);
    return c ? Number(r.statistics?.channelMessageCounts.get(c.id) ?? 0n) : 0;
  };
  check(foveated > 0 && count("/fovea/camera_pose") === foveated,
        `/fovea/camera_pose has one message a frame foveated: ${count("/fovea/camera_pose")} of ${foveated}`);
  check(count("/fovea/frame_summary") === foveated - handoffDrops,
        `/fovea/frame_summary has one summary a frame foveated and not dropped before the send stage (no operator: every such frame encoded): ${count("/fovea/frame_summary")} of ${foveated} - ${handoffDrops}`);
  check(count("/fovea/chunks") >= foveated, `/fovea/chunks has at least a chunk a frame: ${count("/fovea/chunks")} for ${foveated} frames`);
  check(count("/fovea/status") >= 1, `/fovea/status has the status lines: ${count("/fovea/status")}`);
  const chunks = topics.get("/fovea/chunks");
  if (chunks) {
    const schema = r.schemasById.get(chunks.schemaId);
    check(schema?.encoding === "fovea.chunk", `/fovea/chunks' schema encoding is fovea.chunk (${schema?.encoding})`);
    for (const m of stream.messages.filter((x) => x.channelId === chunks.id)) {
      check(m.data.byteLength > 0, "a recorded chunk is not empty");
    }
  }
  // The Foxglove channels: Protobuf with the FileDescriptorSet embedded, decoded
  // here with protobufjs from the file's own schema (an independent reader).
  const protobuf = require("protobufjs");
  require("protobufjs/ext/descriptor");
  const foxglove = { "/fovea/cloud": "foxglove.PointCloud", "/fovea/camera": "foxglove.FrameTransform",
                     "/fovea/log": "foxglove.Log", "/fovea/gaze_ray": "foxglove.SceneUpdate" };
  for (const [topic, name] of Object.entries(foxglove)) {
    const c = topics.get(topic);
    check(c !== undefined && c.messageEncoding === "protobuf", `fovead's recording has ${topic} (protobuf)`);
    if (!c) continue;
    const schema = r.schemasById.get(c.schemaId);
    check(schema?.name === name && schema?.encoding === "protobuf", `${topic}'s schema is ${name} (${schema?.name}, ${schema?.encoding})`);
    if (!schema || topic === "/fovea/gaze_ray") continue;  // no operator here: no gaze
    const type = protobuf.Root.fromDescriptor(protobuf.descriptor.FileDescriptorSet.decode(schema.data)).lookupType(name);
    const messages = stream.messages.filter((x) => x.channelId === c.id);
    check(messages.length > 0, `${topic} has messages (${messages.length})`);
    if (messages.length === 0) continue;
    const m = type.toObject(type.decode(messages[messages.length - 1].data), { longs: Number, defaults: true });
    if (topic === "/fovea/cloud") {
      const points = m.data.length / Math.max(m.point_stride, 1);
      check(m.frame_id === "world" && m.point_stride === 16 && points > 1000 && Number.isInteger(points),
            `/fovea/cloud decodes: frame ${m.frame_id}, stride ${m.point_stride}, ${points} points`);
      check(m.fields.map((f) => f.name).join(",") === "x,y,z,rgba", `/fovea/cloud's fields are x,y,z,rgba (${m.fields.map((f) => f.name)})`);
      const clouds = count("/fovea/cloud");
      check(clouds <= foveated && clouds >= foveated - ringFullDrops,
            `/fovea/cloud has one cloud a frame foveated, less those its full ring dropped: ${clouds} of ${foveated} (ring full ${ringFullDrops})`);
    } else if (topic === "/fovea/camera") {
      check(m.parent_frame_id === "world" && m.child_frame_id === "camera" && m.rotation !== undefined,
            `/fovea/camera decodes: ${m.parent_frame_id} -> ${m.child_frame_id}`);
    } else if (topic === "/fovea/log") {
      check(typeof m.message === "string" && m.message.length > 0, `/fovea/log decodes: "${m.message.slice(0, 40)}"`);
    }
  }
  console.log(`fovead --record: ${stream.messages.length} messages, ${[...topics.keys()].map((t) => `${t}=${count(t)}`).join(" ")}`);
}

// fovead serve --record with fovea-operator connected for a few seconds: the
// gaze it sends (with its HMD pose) is recorded as it came, and the chunks as sent.
async function checkFoveadWithOperator(fovead, operator, workdir) {
  const file = path.join(workdir, "fovead-serve-operator.mcap");
  fs.rmSync(file, { force: true });
  const service = spawn(...command(fovead, ["serve", "--camera", "mock:living-room,size=320x240,realtime=on", "--duration", "6",
                                 "--listen", "127.0.0.1:0", "--insecure", "--record", file]), { stdio: ["ignore", "pipe", "pipe"] });
  let out = "";
  service.stdout.on("data", (d) => { out += d; });
  service.stderr.on("data", () => {});
  const exited = new Promise((resolve) => service.on("exit", (code) => resolve(code)));
  let address;
  for (let i = 0; i < 200 && !address; i++) {
    address = (/streaming: listening on (\S+)/.exec(out) ?? [])[1];
    if (!address) await new Promise((r) => setTimeout(r, 50));
  }
  check(address !== undefined, "fovead serve --record started listening");
  if (address) {
    try {
      execFileSync(...command(operator, ["--connect", address, "--insecure", "--quiet", "--duration", "3",
                              "--gaze", "fixed:0,0,0>0,0,2"]), { stdio: "ignore", timeout: 60000 });
    } catch (e) {
      check(false, `fovea-operator ran: ${e}`);
    }
  }
  check((await exited) === 0, "fovead serve --record exited 0");
  const { indexed, stream } = await readBoth(file);
  const r = indexed.reader;
  const byTopic = new Map([...r.channelsById.values()].map((c) => [c.topic, c.id]));
  const gaze = stream.messages.filter((m) => m.channelId === byTopic.get("/fovea/gaze"));
  check(gaze.length > 10, `/fovea/gaze holds the operator's gaze samples: ${gaze.length}`);
  const chunks = stream.messages.filter((m) => m.channelId === byTopic.get("/fovea/chunks"));
  check(chunks.length > 0, `/fovea/chunks holds the chunks sent: ${chunks.length}`);
  // Each gaze sample (confidence > 0) also as Foxglove's arrow, decoded from the file's schema.
  const rays = stream.messages.filter((m) => m.channelId === byTopic.get("/fovea/gaze_ray"));
  check(rays.length > 10 && rays.length <= gaze.length, `/fovea/gaze_ray draws the gaze samples: ${rays.length} of ${gaze.length}`);
  if (rays.length > 0) {
    const protobuf = require("protobufjs");
    require("protobufjs/ext/descriptor");
    const channel = r.channelsById.get(byTopic.get("/fovea/gaze_ray"));
    const schema = r.schemasById.get(channel.schemaId);
    const type = protobuf.Root.fromDescriptor(protobuf.descriptor.FileDescriptorSet.decode(schema.data)).lookupType("foxglove.SceneUpdate");
    const u = type.toObject(type.decode(rays[rays.length - 1].data), { longs: Number, defaults: true });
    const arrow = u.entities[0]?.arrows[0];
    check(u.entities[0]?.id === "gaze" && arrow !== undefined, "/fovea/gaze_ray decodes: an entity 'gaze' with an arrow");
    if (arrow) check(Math.abs(arrow.pose.position.x) < 1e-9 && Math.abs(arrow.pose.position.z) < 1e-9, `the arrow starts at the operator's eye, (0, 0, 0) in its script (x ${arrow.pose.position.x})`);
  }
  console.log(`fovead --record with an operator: ${gaze.length} gaze samples, ${rays.length} gaze rays, ${chunks.length} chunks`);
}

const a = args();
try {
  if (a.writer) {
    fs.mkdirSync(a.workdir, { recursive: true });
    for (const compression of ["zstd", "none"]) {
      const file = path.join(a.workdir, `sample-${compression}.mcap`);
      const manifest = path.join(a.workdir, `sample-${compression}.json`);
      execFileSync(...command(a.writer, [file, manifest, compression]), { stdio: "inherit" });
      await compareManifest(file, manifest);
    }
  } else if (a.fovead) {
    fs.mkdirSync(a.workdir, { recursive: true });
    await checkFovead(a.fovead, a.workdir, Number(a.frames ?? 30));
    if (a.operator) await checkFoveadWithOperator(a.fovead, a.operator, a.workdir);
  } else if (a.file) {
    if (a.manifest) await compareManifest(a.file, a.manifest);
    else await readBoth(a.file);
  } else {
    console.error("usage: check_mcap.mjs --writer PROGRAM --workdir DIR | --fovead FOVEAD --workdir DIR | --file F [--manifest M]");
    process.exit(2);
  }
} catch (e) {
  checks++;
  failures++;
  console.error(`FAIL: ${e.stack ?? e}`);
}
console.log(`check_mcap: ${checks - failures} passed, ${failures} failed`);
process.exit(failures === 0 ? 0 : 1);
