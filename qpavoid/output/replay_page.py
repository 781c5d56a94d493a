"""The replay page: HTML, style and the script that plays a run (:mod:`qpavoid.output.replay_html`
fills in the viewer bundle, the scene commands and the run's arrays).

The script keeps one tick index. The slider (``#time``, seconds) and play/pause
(``#play``, at ``#speed`` times real time) move it; each move shows that tick's numbers
(``#t``, ``#f``, ``#d0``, ``#s0``, ... per robot set (one row of ``#sets`` each, as many
as the robot description has sets), ``#reason``, ``#alert``: a suspect input,
``#safety``) and places every object from the scene frame at or before it. Shapes are
unit cylinders (axis y) and spheres, scaled and placed by one matrix each; a shape that
is not seen is scaled to nothing. The arm's collision objects hang on one group per joint
(``robot/meshes/j<joint>``), placed from the joint's pose (a quaternion and a
translation). The camera starts where ``camera`` says, looking at its ``target``
(MeshCat's camera hangs on a frame turned +90° about x, the three.js y-up convention: a
point (x, y, z) of the base frame is (x, z, −y) there). Check boxes (``#layers``) show or
hide the arm's meshes, the safety shapes, the person and the floor. In live mode
(``LIVE``) the controls are hidden and the script shows the newest tick its server gives
(``state``) ten times a second, and, while the input is suspect, a button (``#clear``)
that asks the server to clear the flagged people (``POST clear``).
``window.qpavoidReplay`` exposes ``seek(t)``, ``tick()``, ``visible(name, on)``,
``objects()``, ``children(path)`` (the names under a path) and ``world(path)`` (the
matrix, in the base frame and column by column, of the object MeshCat keeps at
``path/<object>``) for tests.
"""

__all__ = ["PAGE"]

PAGE = r"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{{TITLE}}</title>
<style>
  body { margin: 0; font: 13px/1.35 system-ui, sans-serif; }
  #meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }
  #panel { position: absolute; left: 10px; top: 10px; z-index: 10; background: #ffffffe8;
           padding: 8px 10px; border-radius: 6px; box-shadow: 0 1px 4px #0004; width: 330px; }
  #panel h1 { font-size: 14px; margin: 0 0 6px; }
  #panel table { border-collapse: collapse; width: 100%; margin: 4px 0; }
  #panel td { padding: 1px 4px; font-variant-numeric: tabular-nums; }
  #controls { display: flex; gap: 6px; align-items: center; }
  #time { flex: 1; }
  .swatch { display: inline-block; width: 10px; height: 10px; border-radius: 2px; }
  #reason { color: #b00; min-height: 1.3em; }
  #alert { color: #a50; }
  #safety { color: #444; }
  #layers { font-size: 12px; }
  #layers label { margin-right: 2px; white-space: nowrap; }
</style>
</head>
<body>
<div id="meshcat-pane"></div>
<div id="panel">
  <h1>{{TITLE}}</h1>
  <div id="controls">
    <button id="play" type="button">Play</button>
    <input id="time" type="range" min="0" max="1" step="0.001" value="0">
    <select id="speed" title="playback speed">
      <option value="0.25">0.25×</option><option value="0.5">0.5×</option>
      <option value="1" selected>1×</option><option value="2">2×</option>
      <option value="4">4×</option>
    </select>
  </div>
  <div id="layers">show:
    <label><input type="checkbox" data-path="robot/meshes" checked> arm</label>
    <label><input type="checkbox" data-path="robot/shapes" checked>
      <span id="shapes-name">safety shapes</span></label>
    <label><input type="checkbox" data-path="human" checked> person</label>
    <label><input type="checkbox" data-path="floor" checked> floor</label>
  </div>
  <div>t = <b id="t"></b> s &nbsp; f = <b id="f"></b> &nbsp; <span id="moving"></span></div>
  <table>
    <thead><tr><td></td><td>distance</td><td>pair</td></tr></thead>
    <tbody id="sets"></tbody>
  </table>
  <div id="reason"></div>
  <div id="alert"></div>
  <button id="clear" type="button" hidden>clear the flagged people</button>
  <div id="safety"></div>
</div>
<script>{{VIEWER}}</script>
<script>
"use strict";
const SCENE = {{SCENE}};
const RAW = {{DATA}};
const COLOURS = {{COLOURS}};
const LIVE = {{LIVE}};

function decode(value) {
  if (value && typeof value === "object" && "b64" in value) {
    const bytes = Uint8Array.from(atob(value.b64), (c) => c.charCodeAt(0));
    const Type = { float32: Float32Array, float64: Float64Array, int32: Int32Array }[value.dtype];
    const array = new Type(bytes.buffer);
    array.shape = value.shape;
    return array;
  }
  if (Array.isArray(value)) return value.map(decode);
  if (value && typeof value === "object") {
    const out = {};
    for (const k in value) out[k] = decode(value[k]);
    return out;
  }
  return value;
}

const D = decode(RAW);
const nSets = D.set_names.length;  // one row of numbers per robot set
for (let s = 0; s < nSets; s++) {
  const row = document.getElementById("sets").insertRow();
  for (const id of ["n", "d"]) row.insertCell().id = id + s;
  const pair = row.insertCell();
  const swatch = document.createElement("span");
  swatch.className = "swatch";
  swatch.id = "c" + s;
  const label = document.createElement("span");
  label.id = "s" + s;
  pair.append(swatch, " ", label);
}
const viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
for (const cmd of SCENE) {
  viewer.handle_command_bytearray(Uint8Array.from(atob(cmd), (c) => c.charCodeAt(0)));
}
// the camera: above and in front of the arm and the person, looking at them; MeshCat's
// camera hangs on a frame turned +90 deg about x, where the base's (x, y, z) is (x, z, -y)
function turned(p) { return [p[0], p[2], -p[1]]; }
viewer.camera.position.set(...turned(D.camera.position));
viewer.controls.target.set(...turned(D.camera.target));
viewer.controls.update();
for (const box of document.querySelectorAll("#layers input")) {
  box.addEventListener("change", () => {
    viewer.handle_command({ type: "set_property", path: "/qpavoid/" + box.dataset.path,
                            property: "visible", value: box.checked });
  });
}
document.getElementById("shapes-name").textContent = D.method;
if (D.arm_parts.length === 0) {  // a URDF without collision objects
  document.querySelector('#layers input[data-path="robot/meshes"]').parentElement.hidden = true;
}

const ZERO = [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1];
function place(path, matrix) {
  viewer.handle_command({ type: "set_transform", path: "/qpavoid/" + path, matrix: matrix });
}
function vec(array, offset) { return [array[offset], array[offset + 1], array[offset + 2]]; }
function finite(p) { return p.every(Number.isFinite); }
function sphere(p, r) {
  if (!finite(p) || !(r > 0)) return ZERO;
  return [r, 0, 0, 0, 0, r, 0, 0, 0, 0, r, 0, p[0], p[1], p[2], 1];
}
function cylinder(a, b, r) {  // a unit cylinder (axis y) from a to b with radius r
  if (!finite(a) || !finite(b)) return ZERO;
  const d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
  const L = Math.hypot(d[0], d[1], d[2]);
  const y = L > 1e-9 ? d.map((v) => v / L) : [0, 0, 1];
  const h = Math.abs(y[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
  let x = [y[1] * h[2] - y[2] * h[1], y[2] * h[0] - y[0] * h[2], y[0] * h[1] - y[1] * h[0]];
  const n = Math.hypot(x[0], x[1], x[2]);
  x = x.map((v) => v / n);
  const z = [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]];
  const m = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2];
  return [x[0] * r, x[1] * r, x[2] * r, 0, y[0] * L, y[1] * L, y[2] * L, 0,
          z[0] * r, z[1] * r, z[2] * r, 0, m[0], m[1], m[2], 1];
}
function pose(a, o) {  // a quaternion (x, y, z, w) and a translation at a[o..o+7)
  const x = a[o], y = a[o + 1], z = a[o + 2], w = a[o + 3];
  return [1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w), 0,
          2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w), 0,
          2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y), 0,
          a[o + 4], a[o + 5], a[o + 6], 1];
}
function capsule(path, a, b, r) {
  place(path + "/body", cylinder(a, b, r));
  place(path + "/a", sphere(a, r));
  place(path + "/b", sphere(b, r));
}

let nTicks = D.t.length;
let nFrames = D.frame_tick.length;
const spheres = D.method === "spheres";
let tick = 0, playing = false, lastWall = null, playT = 0;  // playT: playback time, s

function showFrame(j) {
  const nl = D.links.shape[1];
  for (let i = 0; i + 1 < nl; i++) {
    const o = (j * nl + i) * 3;
    place("robot/link" + i, cylinder(vec(D.links, o), vec(D.links, o + 3), 0.035));
  }
  place("robot/ee", sphere(vec(D.links, (j * nl + nl - 1) * 3), 0.02));
  const nm = D.mesh_joints.length;
  for (let m = 0; m < nm; m++) {
    place("robot/meshes/j" + D.mesh_joints[m], pose(D.mesh_poses, (j * nm + m) * 7));
  }
  const groups = [["robot", D.robot, D.robot_radii], ["human", D.human, D.human_radii]];
  for (const [who, shapes, radii] of groups) {
    const n = shapes.shape[1];
    for (let i = 0; i < n; i++) {
      if (spheres) {
        place(who + "/shapes/" + i, sphere(vec(shapes, (j * n + i) * 3), radii[i]));
      } else {
        const o = (j * n + i) * 6;
        capsule(who + "/shapes/" + i, vec(shapes, o), vec(shapes, o + 3), radii[i]);
      }
    }
  }
}

function showPairs(j, k) {
  for (let s = 0; s < nSets; s++) {
    const o = (j * nSets + s) * 6;
    const a = vec(D.pairs, o), b = vec(D.pairs, o + 3);
    for (let c = 0; c < D.pair_states.length; c++) {
      const shown = c === D.state[k * nSets + s];
      place("pairs/set" + s + "/" + c, shown ? cylinder(a, b, 0.006) : ZERO);
    }
  }
}

function fmt(v, digits) { return Number.isFinite(v) ? v.toFixed(digits) : "none"; }

function showNumbers(k) {
  document.getElementById("t").textContent = D.t[k].toFixed(3);
  document.getElementById("f").textContent = D.f[k].toFixed(3);
  document.getElementById("moving").textContent = D.stopped[k] ? "stopped" : "moving";
  for (let s = 0; s < nSets; s++) {
    const state = D.pair_states[D.state[k * nSets + s]];
    document.getElementById("n" + s).textContent = D.set_names[s];
    document.getElementById("d" + s).textContent = fmt(D.distance[k * nSets + s], 3) + " m";
    document.getElementById("s" + s).textContent = state;
    document.getElementById("c" + s).style.background =
      "#" + COLOURS[state].toString(16).padStart(6, "0");
  }
  document.getElementById("reason").textContent =
    D.stopped[k] ? "stopped: " + (D.reasons[D.reason[k]] || "") : "";
  const alert = D.alert && D.alert[k] >= 0 ? D.alerts[D.alert[k]] : "";
  document.getElementById("alert").textContent = alert ? "suspect input: " + alert : "";
  document.getElementById("clear").hidden = !(LIVE && alert);
  const truth = Array.from({ length: nSets }, (_, s) => D.true_distance[k * nSets + s]);
  const clearance = truth.map((v) => fmt(v, 3)).join(" / ");
  document.getElementById("safety").textContent =
    "frame age " + fmt(D.frame_age[k] * 1000, 0) + " ms" +
    (truth.some(Number.isFinite) ? "; true clearance " + clearance + " m" : "") +
    (D.safety ? "; safety: " + D.safety : "");
}

function tickAt(t) {  // the last tick at or before t
  let lo = 0, hi = nTicks - 1;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (D.t[mid] <= t + 1e-9) lo = mid; else hi = mid - 1;
  }
  return lo;
}
function frameAt(k) {  // the last scene frame at or before tick k
  let lo = 0, hi = nFrames - 1;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (D.frame_tick[mid] <= k) lo = mid; else hi = mid - 1;
  }
  return lo;
}

function show(k) {
  tick = Math.max(0, Math.min(nTicks - 1, k));
  const j = frameAt(tick);
  showFrame(j);
  showPairs(j, tick);
  showNumbers(tick);
}

const slider = document.getElementById("time");
slider.min = D.t[0];
slider.max = D.t[nTicks - 1];
slider.step = nTicks > 1 ? (D.t[nTicks - 1] - D.t[0]) / (nTicks - 1) : 1;
slider.addEventListener("input", () => {
  playT = parseFloat(slider.value);
  show(tickAt(playT));
});
document.getElementById("play").addEventListener("click", () => {
  playing = !playing;
  document.getElementById("play").textContent = playing ? "Pause" : "Play";
  if (playing && tick >= nTicks - 1) show(0);
  playT = D.t[tick];
  lastWall = null;
});
function frame(wall) {
  if (playing) {
    if (lastWall !== null) {
      const speed = parseFloat(document.getElementById("speed").value);
      playT += (wall - lastWall) / 1000 * speed;  // kept apart from the tick: no drift
      show(tickAt(playT));
      slider.value = D.t[tick];
      if (tick >= nTicks - 1) {
        playing = false;
        document.getElementById("play").textContent = "Play";
      }
    }
    lastWall = wall;
  }
  requestAnimationFrame(frame);
}
show(0);
requestAnimationFrame(frame);
if (LIVE) {  // a run as it happens: the newest tick from the server, ten times a second
  document.getElementById("controls").style.display = "none";
  document.getElementById("clear").addEventListener("click", () => {
    fetch("clear", { method: "POST", cache: "no-store" });
  });
  const poll = () => fetch("state", { cache: "no-store" })
    .then((r) => r.json())
    .then((raw) => {
      if (raw) { Object.assign(D, decode(raw)); nTicks = 1; nFrames = 1; show(0); }
    })
    .catch(() => { document.getElementById("reason").textContent = "the run has ended"; })
    .finally(() => setTimeout(poll, 100));
  poll();
}

window.qpavoidReplay = {
  seek: (t) => { slider.value = t; playT = t; show(tickAt(t)); return tick; },
  tick: () => tick,
  visible: (name, on) => viewer.handle_command(
    { type: "set_property", path: "/qpavoid/" + name, property: "visible", value: on }),
  objects: () => Object.keys(viewer.scene_tree.find(["qpavoid"]).children),
  children: (path) => Object.keys(viewer.scene_tree.find(["qpavoid", ...path.split("/")]).children),
  world: (path) => {  // relative to /qpavoid: MeshCat turns the whole scene to y-up
    const root = viewer.scene_tree.find(["qpavoid"]).object;
    const node = viewer.scene_tree.find(["qpavoid", ...path.split("/")]);
    const object = ("<object>" in node.children ? node.children["<object>"] : node).object;
    object.updateWorldMatrix(true, false);
    const matrix = root.matrixWorld.clone().invert().multiply(object.matrixWorld);
    return Array.from(matrix.elements);
  },
};
</script>
</body>
</html>
"""
