// Validates a glTF or GLB file with the Khronos glTF validator (npm package gltf-validator) and
// prints its report as one line of JSON (tests/export_cli_test.cc reads it).
// Usage: node gltf_validate.js NODE_MODULES_DIR FILE
'use strict';
const fs = require('fs');
const path = require('path');

const validator = require(path.join(process.argv[2], 'gltf-validator'));
const file = process.argv[3];
const bytes = new Uint8Array(fs.readFileSync(file));
validator
  .validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 200,
    // A GLB holds its buffer and images: anything else it names is an error.
    externalResourceFunction: (uri) => Promise.reject(new Error('external resource ' + uri)),
  })
  .then((report) => {
    process.stdout.write(JSON.stringify(report) + '\n');
  })
  .catch((error) => {
    process.stderr.write('gltf-validator: ' + error + '\n');
    process.exit(2);
  });
