// Runs the viewer page's script in node against stub DOM and WebGL objects: it must decode its
// data, build its buffers, draw, pick a patch on hover and show that patch's values.
// Usage: node run_page.js PAGE.html; prints a JSON report.
"use strict";
const fs = require("fs");
const text = fs.readFileSync(process.argv[2], "utf8");
const data = text.match(/<script id="data" type="application\/json">([\s\S]*?)<\/script>/)[1];
const code = text.match(/<script>\n([\s\S]*?)<\/script>/)[1];
const listeners = {};
function element(id) {
  return {
    id, style: {}, dataset: {}, textContent: id === "data" ? data.replace(/<\\\//g, "</") : "",
    width: 300, height: 200, clientWidth: 300, clientHeight: 200,
    addEventListener(kind, fn) { listeners[id + ":" + kind] = fn; },
    getBoundingClientRect() { return { left: 0, top: 0 }; },
    getContext(kind) { return kind === "2d" ? ctx2d : gl; },
    insertAdjacentHTML() {},
  };
}
const elements = {};
const ctx2d = new Proxy({}, { get: (t, k) => (k in t ? t[k] : () => {}), set: (t, k, v) => { t[k] = v; return true; } });
let draws = 0, pickedId = 0, bufferSizes = [];
const gl = new Proxy({}, {
  get(target, key) {
    if (key === "getShaderParameter" || key === "getProgramParameter") return () => true;
    if (key === "drawArrays") return (mode, first, count) => { draws += 1; target.lastCount = count; };
    if (key === "bufferData") return (kind, array) => bufferSizes.push(array.length);
    if (key === "readPixels") return (x, y, w, h, f, t, out) => { out[0] = pickedId & 255; out[1] = (pickedId >> 8) & 255; out[2] = 0; out[3] = 255; };
    if (key === "lastCount") return target.lastCount;
    if (key === "uniformMatrix4fv") return (loc, transpose, m) => { target.matrix = Array.from(m); };
    if (key === "matrix") return target.matrix;
    if (typeof key === "string" && key === key.toUpperCase()) return 1;  // constants
    return () => ({});
  },
});
global.document = {
  getElementById(id) { return elements[id] || (elements[id] = element(id)); },
  body: { dataset: {}, insertAdjacentHTML() {} },
};
global.window = { devicePixelRatio: 1, addEventListener(kind, fn) { listeners["window:" + kind] = fn; } };
new Function(code)();
const D = JSON.parse(data.replace(/<\\\//g, "</"));
const report = { ready: document.body.dataset.ready === "1", draws, n: D.n, lastCount: gl.lastCount, bufferSizes };
// Where the first view puts the scene: the share of corners inside the clip volume.
const bin = Buffer.from(D.position, "base64"), pos = new Float32Array(bin.buffer, bin.byteOffset, bin.length / 4);
const m = gl.matrix;
let inside = 0;
for (let v = 0; v < D.n; v++) {
  const p = [pos[3 * v], pos[3 * v + 1], pos[3 * v + 2], 1];
  const c = [0, 1, 2, 3].map(r => m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r] * p[3]);
  if (c[3] > 0 && [0, 1, 2].every(k => Math.abs(c[k]) <= c[3] * 1.0001)) inside += 1;
}
report.insideFraction = inside / D.n;
pickedId = 1 + 3;  // the pick pass answers: patch 3 under the mouse
listeners["view:mousemove"]({ clientX: 10, clientY: 20 });
report.tip = elements.tip.textContent;
report.tipShown = elements.tip.style.display;
pickedId = 0;  // background
listeners["view:mousemove"]({ clientX: 1, clientY: 1 });
report.tipOnBackground = elements.tip.style.display;
listeners["view:mousedown"]({ clientX: 0, clientY: 0 });
listeners["view:mousemove"]({ clientX: 30, clientY: 5 });
listeners["window:mouseup"]({});
listeners["mode:click"]({ target: elements.mode });
report.modeButton = elements.mode.textContent;
report.barTitle = elements.barTitle.textContent;
report.drawsAfter = draws;
console.log(JSON.stringify(report));
