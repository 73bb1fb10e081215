// Runs the Khronos glTF validator (npm gltf-validator) on one .gltf/.glb file and prints a
// JSON summary: counts of errors, warnings, infos and hints, and the first 20 errors and
// warnings. Exit status 0 when there are neither errors nor warnings, 1 when there are, 2
// when the file cannot be validated. Used by tests/cmd/bake_cli_test.cpp.
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');
const file = process.argv[2];
if (!file) {
  console.error('usage: node validate_gltf.js FILE.gltf|FILE.glb');
  process.exit(2);
}
const bytes = new Uint8Array(fs.readFileSync(file));
validator.validateBytes(bytes, {
  uri: file,
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)), (err, data) => err ? reject(err.toString()) : resolve(new Uint8Array(data)));
  }),
}).then((report) => {
  const i = report.issues;
  console.log(JSON.stringify({errors: i.numErrors, warnings: i.numWarnings, infos: i.numInfos, hints: i.numHints,
    messages: i.messages.filter(m => m.severity <= 1).slice(0, 20).map(m => `${m.code} ${m.pointer || ''} ${m.message}`)}, null, 1));
  process.exit(i.numErrors + i.numWarnings > 0 ? 1 : 0);
}).catch((e) => { console.error(e); process.exit(2); });
