// Validate glTF files with the Khronos glTF-Validator (npm gltf-validator).
// Usage: node web/validate.mjs FILE.glb|FILE.gltf ...
// Prints one JSON report per line ({file, errors, warnings, infos, messages}); exit code 1
// when any file has an error.
import fs from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';

let failed = false;
for (const file of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 50,
    externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri}: not allowed`)),
  });
  const issues = report.issues;
  failed = failed || issues.numErrors > 0;
  console.log(JSON.stringify({
    file, errors: issues.numErrors, warnings: issues.numWarnings, infos: issues.numInfos,
    messages: issues.messages.map((m) => ({ severity: m.severity, code: m.code, message: m.message, pointer: m.pointer })),
  }));
}
process.exit(failed ? 1 : 0);
