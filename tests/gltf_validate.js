#!/usr/bin/env node
// The Khronos glTF validator (npm package gltf-validator, installed into web/node_modules by
// scripts/setup.sh) on each file given: .glb, or .gltf with its .bin beside it. Prints the
// validator's counts per file; exit 1 when any file has an error or a warning, 77 (ctest: skipped)
// when the validator is not installed.
"use strict";
const fs = require("fs");
const path = require("path");
let validator;
try {
  validator = require("gltf-validator");
} catch (e) {
  console.log("SKIP: gltf-validator is not installed (scripts/setup.sh installs it into web/node_modules)");
  process.exit(77);
}
async function main() {
  let bad = 0;
  for (const f of process.argv.slice(2)) {
    const r = await validator.validateBytes(new Uint8Array(fs.readFileSync(f)), {
      uri: path.basename(f),
      externalResourceFunction: (uri) =>
        new Promise((resolve, reject) => {
          try {
            resolve(new Uint8Array(fs.readFileSync(path.join(path.dirname(f), decodeURIComponent(uri)))));
          } catch (e) {
            reject(e.toString());
          }
        }),
    });
    const i = r.issues;
    console.log(`${f}: validator ${r.validatorVersion}: ${i.numErrors} errors, ${i.numWarnings} warnings, ` +
      `${i.numInfos} infos, ${i.numHints} hints; ${r.info.totalVertexCount} vertices over ` +
      `${r.info.drawCallCount} draw calls, ${r.info.totalTriangleCount} triangles`);
    for (const m of i.messages.slice(0, 10)) console.log(`  ${m.severity} ${m.code} ${m.pointer || ""}: ${m.message}`);
    if (i.numErrors > 0 || i.numWarnings > 0) bad++;
  }
  process.exit(bad ? 1 : 0);
}
main().catch((e) => {
  console.error(e);
  process.exit(1);
});
