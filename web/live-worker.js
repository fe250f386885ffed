// The live page's worker (bounce view --live): the Neumann series E + KE + K^2E + ... on F as the page
// embeds it (bn_transport_links: a tree of nodes above the patches, links between nodes; dense and sparse
// F are the flat case, one leaf per patch). K = diag(rho) F, rho and E per patch from the materials the
// sliders set. Sums in double (Float64Array), F in float as stored. Runs in a Web Worker in the page and
// under node for the tests (module.exports).
"use strict";

const NONE = 0xffffffff;

// The operator from the payload's arrays: y = F x, x and y 3 per patch. kernel: web/live-kernel.c's bytes
// (WebAssembly with SIMD), or null/empty for the JavaScript loops; both give the same doubles.
function makeOperator(a, npatch, kernel) {
  const n = a.child.length, parent = new Uint32Array(n).fill(NONE);
  for (let v = 0; v < n; v++) if (a.child[v] !== NONE) parent[a.child[v]] = parent[a.child[v] + 1] = v;
  const flat = n === npatch && a.cluster.every((c) => c === 0) && a.child.every((c) => c === NONE) &&
    a.leaf_patch.every((p, v) => p === v);
  const anyCluster = a.cluster.some((c) => c !== 0);
  const B = new Float64Array(3 * n), G = new Float64Array(3 * n), Gv = anyCluster ? new Float64Array(9 * n) : null;
  const op = { n, flat, parent, B, G, Gv, a, npatch, wasm: makeKernel(kernel, a, n), clusterRows: clusterRows(a, n) };
  op.apply = (x, y) => (flat ? applyFlat(op, x, y) : applyTree(op, x, y));
  return op;
}

function clusterRows(a, n) {
  const out = [];
  for (let r = 0; r < n; r++) if (a.cluster[r]) out.push(r);
  return Uint32Array.from(out);
}

// The WebAssembly gather over a copy of the links in its own memory (after __heap_base: start, src, F, the
// cluster flags, then x and y, 4 doubles per node), or null where WebAssembly or its SIMD is missing.
function makeKernel(bytes, a, n) {
  if (!bytes || !bytes.length || typeof WebAssembly === "undefined") return null;
  let inst, mem;
  try {
    mem = new WebAssembly.Memory({ initial: 32 });
    inst = new WebAssembly.Instance(new WebAssembly.Module(bytes), { env: { memory: mem } });
  } catch (e) {
    return null;
  }
  const L = a.F.length, up = (v) => Math.ceil(v / 16) * 16, off = [up(inst.exports.__heap_base.value)];
  for (const size of [4 * (n + 1), 4 * L, 4 * L, n, 32 * n, 32 * n]) off.push(up(off[off.length - 1] + size));
  const need = off[off.length - 1] - mem.buffer.byteLength;
  try {
    if (need > 0) mem.grow(Math.ceil(need / 65536));
  } catch (e) {
    return null;   // above WebAssembly's 4 GiB (or the browser's limit): the JavaScript loop
  }
  const buf = mem.buffer;
  new Uint32Array(buf, off[0], n + 1).set(a.start);
  new Uint32Array(buf, off[1], L).set(a.src);
  new Float32Array(buf, off[2], L).set(a.F);
  new Uint8Array(buf, off[3], n).set(a.cluster);
  const x = new Float64Array(buf, off[4], 4 * n), y = new Float64Array(buf, off[5], 4 * n);
  return { x, y, run: () => inst.exports.gather(n, off[0], off[1], off[2], off[3], off[4], off[5]) };
}

// y (3 per row) = the links' gather of x (3 per node), by the kernel when there is one.
function gatherPlanar(op, x, y) {
  const K = op.wasm;
  if (!K) return gatherPlanarJs(op, x, y);
  for (let v = 0, n = op.n; v < n; v++) {
    K.x[4 * v] = x[3 * v];
    K.x[4 * v + 1] = x[3 * v + 1];
    K.x[4 * v + 2] = x[3 * v + 2];
  }
  K.run();
  for (let r = 0, n = op.n; r < n; r++) {
    y[3 * r] = K.y[4 * r];
    y[3 * r + 1] = K.y[4 * r + 1];
    y[3 * r + 2] = K.y[4 * r + 2];
  }
}

function gatherPlanarJs(op, x, y) {
  const { start, src, F, cluster } = op.a;
  for (let r = 0; r < op.n; r++) {
    let g0 = 0, g1 = 0, g2 = 0;
    if (!cluster[r]) {
      for (let l = start[r], e = start[r + 1]; l < e; l++) {
        const j = 3 * src[l], f = F[l];
        g0 += f * x[j];
        g1 += f * x[j + 1];
        g2 += f * x[j + 2];
      }
    }
    y[3 * r] = g0;
    y[3 * r + 1] = g1;
    y[3 * r + 2] = g2;
  }
}

// Dense or sparse F: y_i = sum over row i's entries of F_ij x_j, times the row's scale.
function applyFlat(op, x, y) {
  const rs = op.a.rowscale;
  gatherPlanar(op, x, y);
  if (rs) for (let k = 0; k < 3 * op.npatch; k++) y[k] *= rs[(k / 3) | 0];
}

// The octahedral direction of a link (bn_transport_links_dir): 8 bits per axis.
function octDecode(e, u) {
  let x = ((e & 255) / 255) * 2 - 1, y = ((e >> 8) / 255) * 2 - 1;
  const z = 1 - Math.abs(x) - Math.abs(y);
  if (z < 0) {
    const ox = x;
    x = (1 - Math.abs(y)) * (ox >= 0 ? 1 : -1);
    y = (1 - Math.abs(ox)) * (y >= 0 ? 1 : -1);
  }
  const l = Math.hypot(x, y, z);
  u[0] = x / l;
  u[1] = y / l;
  u[2] = z / l;
}

// Pull: each node's value, the area-weighted mean of its children's (children after parents).
function pull(op, x) {
  const { child, leaf_patch: leaf, area } = op.a, B = op.B;
  for (let v = op.n - 1; v >= 0; v--) {
    const c = child[v];
    if (c === NONE) {
      const p = 3 * leaf[v];
      B[3 * v] = x[p];
      B[3 * v + 1] = x[p + 1];
      B[3 * v + 2] = x[p + 2];
    } else {
      const a0 = area[c], a1 = area[c + 1], inv = 1 / area[v];
      for (let k = 0; k < 3; k++) B[3 * v + k] = (a0 * B[3 * c + k] + a1 * B[3 * (c + 1) + k]) * inv;
    }
  }
}

// Gather along each receiver's links: a value per channel (gatherPlanar), or a cluster's vector per channel.
function gather(op) {
  gatherPlanar(op, op.B, op.G);
  if (op.clusterRows.length) gatherClusters(op);
}

// A cluster receiver's vector per channel: the sum over its links of F B u, u the link's direction (decoded
// once, clusterDirs). Gv[9 r + 3 c + k]: channel c, axis k.
function gatherClusters(op) {
  const { start, src, F } = op.a, { B, Gv, clusterRows: rows } = op, u = op.clusterDir || (op.clusterDir = clusterDirs(op));
  for (let i = 0, q = 0; i < rows.length; i++) {
    const r = rows[i];
    let a0 = 0, a1 = 0, a2 = 0, a3 = 0, a4 = 0, a5 = 0, a6 = 0, a7 = 0, a8 = 0;
    for (let l = start[r], e = start[r + 1]; l < e; l++, q += 3) {
      const b = 3 * src[l], f = F[l], f0 = f * B[b], f1 = f * B[b + 1], f2 = f * B[b + 2];
      const u0 = u[q], u1 = u[q + 1], u2 = u[q + 2];
      a0 += f0 * u0; a1 += f0 * u1; a2 += f0 * u2;
      a3 += f1 * u0; a4 += f1 * u1; a5 += f1 * u2;
      a6 += f2 * u0; a7 += f2 * u1; a8 += f2 * u2;
    }
    const g = 9 * r;
    Gv[g] = a0; Gv[g + 1] = a1; Gv[g + 2] = a2;
    Gv[g + 3] = a3; Gv[g + 4] = a4; Gv[g + 5] = a5;
    Gv[g + 6] = a6; Gv[g + 7] = a7; Gv[g + 8] = a8;
  }
}

// The directions of the cluster receivers' links, 3 per link in clusterRows' order.
function clusterDirs(op) {
  const { start, dir } = op.a, rows = op.clusterRows, u = [0, 0, 0];
  let n = 0;
  for (const r of rows) n += start[r + 1] - start[r];
  const out = new Float64Array(3 * n);
  for (let i = 0, q = 0; i < rows.length; i++)
    for (let l = start[rows[i]]; l < start[rows[i] + 1]; l++, q += 3) {
      octDecode(dir[l], u);
      out.set(u, q);
    }
  return out;
}

// Push: down the tree (clusters' vectors to clusters, dotted with a polygon's normal below a cluster,
// values to planar nodes), then each leaf into its patch.
function push(op, y) {
  const { cluster, normal, leaf_patch: leaf, rowscale: rs } = op.a, { parent, G, Gv } = op;
  for (let v = 1; v < op.n; v++) {
    const p = parent[v];
    if (cluster[v]) {
      for (let k = 0; k < 9; k++) Gv[9 * v + k] += Gv[9 * p + k];
    } else if (cluster[p]) {
      for (let c = 0; c < 3; c++)
        G[3 * v + c] += normal[3 * v] * Gv[9 * p + 3 * c] + normal[3 * v + 1] * Gv[9 * p + 3 * c + 1] +
          normal[3 * v + 2] * Gv[9 * p + 3 * c + 2];
    } else {
      for (let c = 0; c < 3; c++) G[3 * v + c] += G[3 * p + c];
    }
  }
  for (let v = 0; v < op.n; v++) {
    if (leaf[v] === NONE || op.a.child[v] !== NONE) continue;
    const i = leaf[v], s = rs ? rs[i] : 1;
    for (let c = 0; c < 3; c++) y[3 * i + c] = s * G[3 * v + c];
  }
}

function applyTree(op, x, y) {
  pull(op, x);
  gather(op);
  push(op, y);
}

// Per patch reflectance and emission from the materials' values (M x 3) and the texture factors.
function patchValues(P, matValues, factor) {
  const out = new Float64Array(3 * P.npatch);
  for (let i = 0; i < P.npatch; i++) {
    const m = 3 * P.patch_material[i];
    for (let c = 0; c < 3; c++) out[3 * i + c] = matValues[m + c] * factor[3 * i + c];
  }
  return out;
}

// The first answer, sent while the series goes on: the terms so far, and rest as the geometric tail of the
// last term (per channel, its ratio q to the one before: rest ~ K^b E q / (1 - q)). Exact but for rest.
function partial(terms, L, applies) {
  const b = terms.length - 1, last = terms[b], prev = terms[Math.max(0, b - 1)], q = [0, 0, 0], s = [0, 0, 0, 0, 0, 0];
  for (let k = 0; k < last.length; k++) {
    s[k % 3] += last[k];
    s[3 + (k % 3)] += prev[k];
  }
  for (let c = 0; c < 3; c++) q[c] = b >= 2 && s[3 + c] > 0 ? Math.min(0.99, s[c] / s[3 + c]) : 0;
  const rest = new Float64Array(last.length), Lp = Float64Array.from(L);
  for (let k = 0; k < last.length; k++) {
    rest[k] = (last[k] * q[k % 3]) / (1 - q[k % 3]);
    Lp[k] += rest[k];
  }
  return { terms: terms.concat([rest, Lp]), applies, converged: false, partial: true };
}

// A first view (rest estimated) only when the terms alone took this long (ms): a quicker series ends within a
// few times this, and drawing a first view meanwhile slows it (the page, its drawing and the worker share
// the machine's cores: Cornell's series took 40 ms with a first view drawn, 15-20 ms without).
const FIRST_VIEW_AFTER_MS = 10;

// The series for emission E and the punctual lights' white light D x s: terms E .. K^b E, then rest
// (every later term, until a term's sum over patches and channels is below tol times the reflected
// light's, L - E) and L. Returns
// { terms: [Float64Array] (b + 1 of them, then rest, then L), applies, converged }.
function series(P, op, rho, E, D, s, b, tol, maxApplies, onPartial) {
  const n3 = 3 * P.npatch, terms = [Float64Array.from(E)], rest = new Float64Array(n3), L = Float64Array.from(E);
  let x = terms[0], applies = 0, converged = false, reflected = 0;
  const t0 = performance.now();
  while (applies < maxApplies) {
    const y = new Float64Array(n3);
    op.apply(x, y);
    applies++;
    let ysum = 0;
    for (let k = 0; k < n3; k++) {
      y[k] *= rho[k];
      if (applies === 1 && D) y[k] += rho[k] * D[k] * s;
      L[k] += y[k];
      if (applies > b) rest[k] += y[k];
      ysum += y[k];
      reflected += y[k];
    }
    if (applies <= b) terms.push(y);
    if (applies === b && onPartial && performance.now() - t0 >= FIRST_VIEW_AFTER_MS) onPartial(partial(terms, L, applies));
    x = y;
    if (applies >= b && ysum <= tol * reflected) {
      converged = true;
      break;
    }
  }
  while (terms.length < b + 1) terms.push(new Float64Array(n3));
  terms.push(rest, L);
  return { terms, applies, converged };
}

// A solve for the sliders' state: { rho: [M x 3], Le: [M x 3], punctual: s } -> terms, as series();
// light sources solved apart (each emitting material, the punctual lights) when there are few, so that
// a change of Le or of s alone is a weighted sum of their terms (K is linear in E), no new series.
function makeSolver(P, op, opts) {
  const M = P.materials.length, b = opts.bounces, tol = opts.tol, maxApplies = opts.maxApplies;
  let basisRho = null, basis = null;
  const key = (r) => Array.from(r).join(",");
  function solveBases(rhoMat, onPartial) {
    const rho = patchValues(P, rhoMat, P.rho_factor), out = [];
    for (let m = 0; m < M; m++) {
      if (!P.emitting[m]) continue;
      const only = new Float64Array(3 * M);
      only.set([1, 1, 1], 3 * m);
      out.push({ m, r: series(P, op, rho, patchValues(P, only, P.Le_factor), null, 0, b, tol, maxApplies, onPartial) });
    }
    if (P.D_white)
      out.push({ m: -1, r: series(P, op, rho, new Float64Array(3 * P.npatch), P.D_white, 1, b, tol, maxApplies, onPartial) });
    return out;
  }
  function solve(state, onPartial) {
    const rhoMat = Float64Array.from(state.rho), LeMat = Float64Array.from(state.Le);
    const useBasis = P.sources <= opts.maxSources && P.materials.every((m, k) => P.emitting[k] ||
      (LeMat[3 * k] === 0 && LeMat[3 * k + 1] === 0 && LeMat[3 * k + 2] === 0));
    if (!useBasis) {
      const rho = patchValues(P, rhoMat, P.rho_factor);
      return series(P, op, rho, patchValues(P, LeMat, P.Le_factor), P.D_white, state.punctual, b, tol, maxApplies,
                    onPartial);
    }
    let fresh = false;
    if (basisRho !== key(rhoMat)) {
      basis = solveBases(rhoMat, onPartial && P.sources === 1 ?
        (r) => onPartial(combine(P, [{ m: P.D_white ? -1 : P.emitting.indexOf(true), r }], LeMat, state.punctual, b, true)) : null);
      basisRho = key(rhoMat);
      fresh = true;
    }
    return combine(P, basis, LeMat, state.punctual, b, fresh);
  }
  solve.loop = op.wasm ? "WebAssembly" : "JavaScript";
  return solve;
}

// The terms for Le and s from the sources' own terms (Le per channel times each source's white terms).
function combine(P, basis, LeMat, s, b, fresh) {
  const n3 = 3 * P.npatch, terms = [];
  let applies = 0, converged = true;
  for (let t = 0; t < b + 3; t++) terms.push(new Float64Array(n3));
  for (const { m, r } of basis) {
    applies += fresh ? r.applies : 0;
    converged = converged && r.converged;
    for (let t = 0; t < b + 3; t++) {
      const src = r.terms[t], dst = terms[t];
      for (let i = 0; i < P.npatch; i++)
        for (let c = 0; c < 3; c++) dst[3 * i + c] += (m < 0 ? s : LeMat[3 * m + c]) * src[3 * i + c];
    }
  }
  return { terms, applies, converged, partial: basis.some((x) => x.r.partial) };
}

// The payload ("BNLV" + JSON + arrays, bn_pipeline_live_write) as typed arrays over its bytes.
function parsePayload(bytes) {
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (dv.getUint32(0, true) !== 0x564c4e42) throw new Error("not a live payload");
  const jlen = dv.getUint32(8, true), json = JSON.parse(new TextDecoder().decode(bytes.subarray(12, 12 + jlen)));
  const base = bytes.byteOffset + 12 + jlen, T = { f32: Float32Array, u32: Uint32Array, u16: Uint16Array, u8: Uint8Array };
  const view = (spec) => new T[spec[2]](bytes.buffer, base + spec[0], spec[1]);
  const P = { json, npatch: json.patches, materials: json.materials, F: {} };
  for (const [k, spec] of Object.entries(json.arrays)) P[k] = view(spec);
  for (const [k, spec] of Object.entries(json.arrays_F)) P.F[k] = view(spec);
  const used = new Uint8Array(json.materials.length);   // materials some patch has (one pass)
  for (let i = 0; i < P.npatch; i++) used[P.patch_material[i]] = 1;
  P.emitting = json.materials.map((m, k) => used[k] === 1 && (m.Le[0] > 0 || m.Le[1] > 0 || m.Le[2] > 0));
  P.sources = P.emitting.filter((e) => e).length + (P.D_white ? 1 : 0);
  return P;
}

// One change of the sliders: the terms as float32 (E .. K^b E, rest, L) and what it cost; send (may be
// null) receives the first answer before the series is done.
function run(P, solve, state, send) {
  const t0 = performance.now(), pack = (r) => ({ terms: r.terms.map((t) => Float32Array.from(t)), applies: r.applies,
                                                 converged: r.converged, partial: !!r.partial, ms: performance.now() - t0,
                                                 loop: solve.loop });
  return pack(solve(state, send ? (r) => send(pack(r)) : null));
}

if (typeof module !== "undefined") {
  module.exports = { parsePayload, makeOperator, makeSolver, series, patchValues, run };
} else {
  let P = null, solve = null;
  self.onmessage = (e) => {
    const d = e.data;
    if (d.payload) {
      P = parsePayload(new Uint8Array(d.payload));
      const op = makeOperator(P.F, P.npatch, d.kernel ? new Uint8Array(d.kernel) : null);
      solve = makeSolver(P, op, d.opts);
      return;
    }
    const post = (out) => {
      out.id = d.id;
      self.postMessage(out, out.terms.map((t) => t.buffer));
    };
    post(run(P, solve, d.state, post));
  };
}
