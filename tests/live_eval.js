// The live page's worker (web/live-worker.js) run under node on a page's embedded payload: prints, as JSON,
// every term per patch (E .. K^b E, rest, L) for the page's materials with the edits given, and the solve's
// L the page carries. For tests/live_check.py.
//   node live_eval.js WORKER.js PAGE.html '{"rho": {"red": [0.1, 0.6, 0.1]}, "Le": {...}, "punctual": 1}' [js]
// The page's WebAssembly kernel (web/live-kernel.c) is used when the page has one, unless "js" is given.
"use strict";
const fs = require("fs");
const W = require(require("path").resolve(process.argv[2]));
const html = fs.readFileSync(process.argv[3], "utf8"), edits = JSON.parse(process.argv[4] || "{}");
const m = html.match(/const LIVE = "([A-Za-z0-9+/=]*)"/);
if (!m || !m[1]) throw new Error(process.argv[3] + ": no live payload");
const P = W.parsePayload(new Uint8Array(Buffer.from(m[1], "base64")));
const k = html.match(/liveStart\(LIVE, "[A-Za-z0-9+/=]*", "([A-Za-z0-9+/=]*)"\)/);
const kernel = process.argv[5] === "js" || !k ? null : new Uint8Array(Buffer.from(k[1], "base64"));
const op = W.makeOperator(P.F, P.npatch, kernel);
const state = { rho: [], Le: [], punctual: edits.punctual ?? 1 };
for (const mat of P.materials) {
  state.rho.push(...((edits.rho || {})[mat.name] || mat.rho));
  state.Le.push(...((edits.Le || {})[mat.name] || mat.Le));
}
const solve = W.makeSolver(P, op, { bounces: P.json.bounces, tol: 1e-7, maxApplies: 5000,
                                                                 maxSources: 4 });
const r = W.run(P, solve, state, null);
process.stdout.write(JSON.stringify({ terms: r.terms.map((t) => Array.from(t)), applies: r.applies, converged: r.converged,
                                      L_solved: P.L_solved ? Array.from(P.L_solved) : null, nodes: P.json.nodes,
                                      links: P.json.links, transport: P.json.transport, kernel: kernel ? kernel.length : 0,
                                      wasm: !!op.wasm }));
