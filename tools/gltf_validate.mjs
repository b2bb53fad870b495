// Run the Khronos glTF validator (npm `gltf-validator`, installed into .tools/ by
// tools/setup-test-tools.sh) on glTF/GLB files and print one JSON report per file, one a line:
//   node tools/gltf_validate.mjs FILE [FILE...]
// Each line: {"file", "errors", "warnings", "infos", "hints", "messages": [{code, message, severity, pointer}]}
// (severity 0 = error). Exit status 0 when every file has 0 errors, 1 otherwise, 2 on usage or I/O errors.
import { createRequire } from "module";
import fs from "fs";
import path from "path";
import { fileURLToPath } from "url";

const here = path.dirname(fileURLToPath(import.meta.url));
const require = createRequire(path.join(here, "..", ".tools", "package.json"));
let validator;
try {
  validator = require("gltf-validator");
} catch (e) {
  console.error("gltf-validator is not installed in .tools/: run tools/setup-test-tools.sh");
  process.exit(2);
}

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error("usage: node tools/gltf_validate.mjs FILE [FILE...]");
  process.exit(2);
}
let bad = 0;
for (const file of files) {
  const dir = path.dirname(path.resolve(file));
  const externalResourceFunction = (uri) =>
    new Promise((resolve, reject) => {
      const p = path.resolve(dir, decodeURIComponent(uri));
      if (!p.startsWith(dir + path.sep)) return reject(new Error(`uri leaves the folder: ${uri}`));
      fs.readFile(p, (err, data) => (err ? reject(err) : resolve(new Uint8Array(data))));
    });
  try {
    const data = new Uint8Array(fs.readFileSync(file));
    const report = await validator.validateBytes(data, {
      uri: path.basename(file), externalResourceFunction, maxIssues: 200,
    });
    const i = report.issues;
    const messages = i.messages.map((m) => ({ code: m.code, message: m.message, severity: m.severity, pointer: m.pointer }));
    console.log(JSON.stringify({ file, errors: i.numErrors, warnings: i.numWarnings, infos: i.numInfos,
      hints: i.numHints, messages, info: report.info }));
    if (i.numErrors > 0) bad += 1;
  } catch (e) {
    console.log(JSON.stringify({ file, errors: 1, warnings: 0, infos: 0, hints: 0,
      messages: [{ code: "IO_ERROR", message: String(e), severity: 0, pointer: "" }] }));
    bad += 1;
  }
}
process.exit(bad ? 1 : 0);
