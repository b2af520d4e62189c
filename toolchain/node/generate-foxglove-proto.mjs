// Writes the .proto files of the Foxglove messages fovea uses (and of the messages
// they import) from the @foxglove/schemas npm package, at build time (io/foxglove).
// Usage: node generate-foxglove-proto.mjs OUT_DIR Message...
// Writes OUT_DIR/foxglove/<Message>.proto; google/protobuf/timestamp.proto and
// duration.proto come with protoc (Debian's libprotobuf-dev).
import { createRequire } from "node:module";
import { mkdirSync, readFileSync, writeFileSync } from "node:fs";
import { join } from "node:path";

const require = createRequire(import.meta.url);
let internal;
try {
  internal = require("@foxglove/schemas/internal");
} catch (e) {
  console.error(`generate-foxglove-proto: cannot load @foxglove/schemas (${e.message}); run toolchain/setup-host`);
  process.exit(1);
}
const { foxgloveMessageSchemas, foxgloveEnumSchemas, generateProto } = internal;

const [outDir, ...wanted] = process.argv.slice(2);
if (!outDir || wanted.length === 0) {
  console.error("usage: generate-foxglove-proto.mjs OUT_DIR Message...");
  process.exit(2);
}

const done = new Set();
const queue = [...wanted];
while (queue.length > 0) {
  const name = queue.shift();
  if (done.has(name)) continue;
  const schema = foxgloveMessageSchemas[name];
  if (schema === undefined) {
    console.error(`generate-foxglove-proto: @foxglove/schemas has no message ${name}`);
    process.exit(1);
  }
  done.add(name);
  const enums = Object.values(foxgloveEnumSchemas).filter((e) => e.parentSchemaName === name);
  const text = generateProto(schema, enums);
  for (const field of schema.fields) {
    if (field.type.type === "nested" && field.type.schema.protoEquivalent === undefined) queue.push(field.type.schema.name);
  }
  mkdirSync(join(outDir, "foxglove"), { recursive: true });
  const path = join(outDir, "foxglove", `${name}.proto`);
  // Unchanged files keep their time stamp, so protoc and the compiler do not rerun.
  let old = null;
  try { old = readFileSync(path, "utf8"); } catch { /* new */ }
  if (old !== text) writeFileSync(path, text);
}
console.log([...done].sort().join(" "));
