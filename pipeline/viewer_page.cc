// The page of rouen view: HTML, CSS and WebGL 2 code, no data (viewer_data.js holds it). It
// works opened as a file (no server, no network): the data comes by a <script> tag, the
// textures are PNG data URLs.
#include "pipeline/viewer.h"

namespace rouen {

const char* ViewerPageHtml() {
  return R"ROUENPAGE(<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>rouen view</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<style>
  html, body { margin: 0; height: 100%; overflow: hidden; background: #20242a;
               font: 13px/1.35 system-ui, sans-serif; color: #e8e8e8; }
  canvas { display: block; width: 100vw; height: 100vh; cursor: grab; touch-action: none; }
  #panel { position: absolute; top: 8px; left: 8px; padding: 8px 10px; width: 300px;
           background: rgba(20, 22, 26, 0.82); border-radius: 6px; }
  #panel label { display: block; margin-top: 6px; }
  #panel input[type=range] { width: 100%; }
  #panel .value { float: right; font-variant-numeric: tabular-nums; }
  #panel h1 { font-size: 14px; margin: 0 0 4px 0; }
  #panel p { margin: 4px 0 0 0; color: #b8b8b8; font-size: 12px; }
  #message { position: absolute; top: 45%; width: 100%; text-align: center; font-size: 16px; }
</style>
</head>
<body>
<canvas id="view"></canvas>
<div id="panel">
  <h1>rouen view <span id="scene"></span></h1>
  <label>Time (UTC) <span class="value" id="time-value"></span>
    <input id="time" type="range" min="0" max="1000" step="1" value="500"></label>
  <label>Overcast (blocked sunlight) <span class="value" id="overcast-value"></span>
    <input id="overcast" type="range" min="0" max="100" step="1" value="0"></label>
  <label>Exposure (EV) <span class="value" id="exposure-value"></span>
    <input id="exposure" type="range" min="-6" max="6" step="0.1" value="0"></label>
  <label><input id="auto" type="checkbox"> Exposure set for each time and overcast</label>
  <label id="response-label"><input id="response" type="checkbox" checked> Through the camera's
    recovered response (else sRGB)</label>
  <p id="sun"></p>
  <p>Drag to orbit, wheel to zoom, shift-drag to pan. Lighting from rouen's recovered sun,
     sky and environment (Yu &amp; Malik 1998), interpolated between <span id="nbases"></span>
     precomputed times.</p>
</div>
<div id="message"></div>
<script src="viewer_data.js"></script>
<script>
"use strict";
(function () {
const D = window.ROUEN_VIEWER_DATA;
const canvas = document.getElementById("view");
const message = document.getElementById("message");
const viewer = { ready: false, frames: 0 };
let readyResolve, readyReject;
// Resolves once the textures are loaded and drawn (rejects with the reason when they cannot be).
viewer.whenReady = new Promise((resolve, reject) => { readyResolve = resolve; readyReject = reject; });
window.rouenViewer = viewer;
if (!D) { message.textContent = "viewer_data.js is missing or did not load"; console.error(message.textContent); return; }
const gl = canvas.getContext("webgl2", { antialias: true, preserveDrawingBuffer: true });
if (!gl) {
  message.textContent = "This page needs WebGL 2, which this browser did not provide.";
  console.error(message.textContent);
  return;
}
viewer.renderer = gl.getParameter(gl.RENDERER);
document.getElementById("scene").textContent = D.scene;
document.getElementById("nbases").textContent = D.bases.length;

// ---- shaders --------------------------------------------------------------------------------
const VS = `#version 300 es
in vec3 aPos; in vec3 aNormal; in vec2 aUv; in float aRetro; in vec3 aLobe; in vec2 aLobeKN;
in vec2 aShadowUv;
uniform mat4 uViewProj;
out vec3 vPos; out vec3 vNormal; out vec2 vUv; out float vRetro; out vec3 vLobe; out vec2 vKN;
out vec2 vShadowUv;
void main() {
  vPos = aPos; vNormal = aNormal; vUv = aUv; vRetro = aRetro; vLobe = aLobe; vKN = aLobeKN;
  vShadowUv = aShadowUv;
  gl_Position = uViewProj * vec4(aPos, 1.0);
}`;
const FS = `#version 300 es
precision highp float;
precision highp sampler2DArray;
in vec3 vPos; in vec3 vNormal; in vec2 vUv; in float vRetro; in vec3 vLobe; in vec2 vKN;
in vec2 vShadowUv;
uniform sampler2DArray uAlbedo, uVis, uSe, uSeo;
uniform vec2 uAlbScale, uSeScale, uSeoScale;
uniform float uLayer0, uLayer1, uW, uPbs, uExposure, uGamma;
uniform vec3 uSunDir0, uSunDir1, uSunE0, uSunE1, uEye;
uniform sampler2D uLut;
uniform bool uResponse;
uniform float uLogLo, uLogHi;
out vec4 outColor;
const float PI = 3.14159265358979;
vec3 dec(vec3 s, float scale) { return scale * pow(s, vec3(uGamma)); }
// solve/retro.h RetroFactor.
float retroFactor(float retro, vec3 n, vec3 l, vec3 v) {
  if (retro == 0.0) return 1.0;
  float cl = clamp(dot(n, l), 0.0, 1.0), cv = clamp(dot(n, v), 0.0, 1.0);
  vec3 h = l + v; float hn = length(h);
  float cd = hn > 0.0 ? dot(l, h) / hn : 0.0;
  float f1 = retro * (2.0 * cd * cd - 0.5);
  return max(0.0, (1.0 + f1 * pow(1.0 - cl, 5.0)) * (1.0 + f1 * pow(1.0 - cv, 5.0)));
}
// solve/retro.h AmbientRetroFactor.
float ambientRetroFactor(float retro, vec3 n, vec3 v) {
  if (retro == 0.0) return 1.0;
  float c = clamp(dot(n, v), 0.0, 1.0), sv = pow(1.0 - c, 5.0);
  float ea = retro * (2.0 * c / 3.0 + 0.5), easl = retro * (c / 84.0 + 1.0 / 42.0);
  float ea2sl = retro * retro * (11.0 * (1.0 - c * c) / 504.0 + c * c / 252.0 + c / 84.0 + 1.0 / 84.0);
  return max(0.0, 1.0 + easl + sv * (ea + ea2sl));
}
// solve/specular.h LobeShape: eq. 13 (Cz = 1, Cxy = -kappa), or the microfacet lobe where
// kappa is sent as -1.
float lobeShape(vec3 n, vec3 u, vec3 v, float kappa, float e) {
  float un = dot(u, n), vn = dot(v, n);
  if (!(un > 0.0) || !(vn > 0.0)) return 0.0;
  if (kappa < 0.0) {
    float uv = dot(u, v), len = sqrt(max(2.0 + 2.0 * uv, 1e-12));
    float nh = (un + vn) / len, vh = (1.0 + uv) / len;
    if (!(nh > 0.0)) return 0.0;
    float a2 = 2.0 / (e + 2.0), t = nh * nh * (a2 - 1.0) + 1.0;
    float gu = 2.0 * un / (un + sqrt(a2 + (1.0 - a2) * un * un));
    float gv = 2.0 * vn / (vn + sqrt(a2 + (1.0 - a2) * vn * vn));
    float fresnel = 1.0 + 24.0 * pow(max(0.0, 1.0 - vh), 5.0);
    return a2 * a2 / (t * t) * gu * gv * fresnel / (un * vn);
  }
  float b = -kappa * (dot(u, v) - un * vn) + un * vn;
  return b > 0.0 ? pow(b, e) : 0.0;
}
// The sun's share of one basis: rho_sun E_sun D / pi + f_s E_sun, E_sun = sun_e max(0, n.s) V.
vec3 sunTerm(vec3 s, vec3 sunE, float vis, vec3 n, vec3 v, vec3 rhoSun) {
  float c = dot(n, s);
  if (c <= 0.0) return vec3(0.0);
  vec3 e = sunE * (c * vis);
  return rhoSun * e * retroFactor(vRetro, n, s, v) / PI + vLobe * lobeShape(n, s, v, vKN.x, vKN.y) * e;
}
float srgb(float x) { return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055; }
void main() {
  vec3 L = vec3(0.0);
  if (vUv.x >= 0.0) {
    vec3 n = normalize(vNormal);
    vec3 v = normalize(uEye - vPos);
    if (dot(n, v) < 0.0) n = -n;  // seen from behind: as render, light the side facing us
    vec3 rhoSun = dec(texture(uAlbedo, vec3(vUv, 0.0)).rgb, uAlbScale.x);
    vec3 rhoSe = dec(texture(uAlbedo, vec3(vUv, 1.0)).rgb, uAlbScale.y);
    float vis0 = texture(uVis, vec3(vShadowUv, uLayer0)).r;
    float vis1 = texture(uVis, vec3(vShadowUv, uLayer1)).r;
    vec3 se = mix(dec(texture(uSe, vec3(vUv, uLayer0)).rgb, uSeScale.x),
                  dec(texture(uSe, vec3(vUv, uLayer1)).rgb, uSeScale.y), uW);
    vec3 seo = mix(dec(texture(uSeo, vec3(vUv, uLayer0)).rgb, uSeoScale.x),
                   dec(texture(uSeo, vec3(vUv, uLayer1)).rgb, uSeoScale.y), uW);
    vec3 sun = mix(sunTerm(uSunDir0, uSunE0, vis0, n, v, rhoSun),
                   sunTerm(uSunDir1, uSunE1, vis1, n, v, rhoSun), uW);
    // Overcast (§6.3): pbs of the sunlight blocked; E_se between the clear and overcast bases.
    L = (1.0 - uPbs) * sun + ambientRetroFactor(vRetro, n, v) * rhoSe * mix(se, seo, uPbs) / PI;
  }
  if (uResponse) {
    // The camera's digital number for the exposure, from the table over ln exposure.
    vec3 t = clamp((log(max(L * uExposure, vec3(1e-30))) - uLogLo) / (uLogHi - uLogLo), 0.0, 1.0);
    t = t * (1023.0 / 1024.0) + 0.5 / 1024.0;
    outColor = vec4(texture(uLut, vec2(t.r, 0.5)).r, texture(uLut, vec2(t.g, 0.5)).g,
                    texture(uLut, vec2(t.b, 0.5)).b, 1.0);
  } else {
    vec3 c = clamp(L * uExposure, 0.0, 1.0);
    outColor = vec4(srgb(c.r), srgb(c.g), srgb(c.b), 1.0);
  }
}`;
function compile(type, src) {
  const s = gl.createShader(type);
  gl.shaderSource(s, src);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
  return s;
}
const prog = gl.createProgram();
gl.attachShader(prog, compile(gl.VERTEX_SHADER, VS));
gl.attachShader(prog, compile(gl.FRAGMENT_SHADER, FS));
gl.linkProgram(prog);
if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(prog));
gl.useProgram(prog);
const U = {};
for (const name of ["uViewProj", "uAlbedo", "uVis", "uSe", "uSeo", "uAlbScale", "uSeScale",
                    "uSeoScale", "uLayer0", "uLayer1", "uW", "uPbs", "uExposure", "uGamma",
                    "uSunDir0", "uSunDir1", "uSunE0", "uSunE1", "uEye", "uLut", "uResponse",
                    "uLogLo", "uLogHi"])
  U[name] = gl.getUniformLocation(prog, name);

// ---- mesh -----------------------------------------------------------------------------------
function decodeBase64(s) {
  const bin = atob(s);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; ++i) bytes[i] = bin.charCodeAt(i);
  return bytes.buffer;
}
const verts = new Float32Array(decodeBase64(D.mesh.data));
const FPV = D.mesh.floats_per_vertex;
const vbo = gl.createBuffer();
gl.bindBuffer(gl.ARRAY_BUFFER, vbo);
gl.bufferData(gl.ARRAY_BUFFER, verts, gl.STATIC_DRAW);
const vao = gl.createVertexArray();
gl.bindVertexArray(vao);
for (const [name, size, offset] of [["aPos", 3, 0], ["aNormal", 3, 3], ["aUv", 2, 6],
                                    ["aRetro", 1, 8], ["aLobe", 3, 9], ["aLobeKN", 2, 12],
                                    ["aShadowUv", 2, 15]]) {
  const loc = gl.getAttribLocation(prog, name);
  if (loc < 0) continue;
  gl.enableVertexAttribArray(loc);
  gl.vertexAttribPointer(loc, size, gl.FLOAT, false, FPV * 4, offset * 4);
}
const vertexCount = verts.length / FPV;

// ---- textures: 2D arrays of 8-bit PNG layers -------------------------------------------------
function loadImage(url) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error("a texture of viewer_data.js did not decode"));
    img.src = url;
  });
}
gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
// size: {width, height}; one channel (R8, the red of the image) or RGBA8.
async function textureArray(unit, urls, size, oneChannel) {
  const imgs = await Promise.all(urls.map(loadImage));
  const tex = gl.createTexture();
  gl.activeTexture(gl.TEXTURE0 + unit);
  gl.bindTexture(gl.TEXTURE_2D_ARRAY, tex);
  gl.texStorage3D(gl.TEXTURE_2D_ARRAY, 1, oneChannel ? gl.R8 : gl.RGBA8, size.width, size.height,
                  urls.length);
  imgs.forEach((img, layer) => {
    if (img.naturalWidth !== size.width || img.naturalHeight !== size.height)
      throw new Error("a texture is " + img.naturalWidth + "x" + img.naturalHeight + ", not its atlas's size");
    gl.texSubImage3D(gl.TEXTURE_2D_ARRAY, 0, 0, 0, layer, size.width, size.height, 1,
                     oneChannel ? gl.RED : gl.RGBA, gl.UNSIGNED_BYTE, img);
  });
  gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
  gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
  gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
  gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
  return tex;
}

// ---- camera: orbit about a target, ENU in the interface, WebGL (east, up, -north) inside -----
const gl3 = (e) => [e[0], e[2], -e[1]];
const enu = (g) => [g[0], -g[2], g[1]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]); return [a[0] / l, a[1] / l, a[2] / l]; };
const cam = { target: [0, 0, 0], azimuth: 0, elevation: 0, distance: 1, fovX: 50 };
function setCameraEnu(eye, target, fovX) {
  const d = sub(eye, target);  // ENU
  cam.target = target.slice();
  cam.distance = Math.hypot(d[0], d[1], d[2]);
  cam.azimuth = Math.atan2(d[0], d[1]);  // from north through east, of the eye seen from the target
  cam.elevation = Math.asin(Math.max(-1, Math.min(1, d[2] / cam.distance)));
  cam.fovX = fovX;
}
function eyeEnu() {
  const c = Math.cos(cam.elevation);
  return [cam.target[0] + cam.distance * c * Math.sin(cam.azimuth),
          cam.target[1] + cam.distance * c * Math.cos(cam.azimuth),
          cam.target[2] + cam.distance * Math.sin(cam.elevation)];
}
// Column-major view-projection of a pinhole camera with horizontal field of view fovX: the
// same camera as rouen render --from-point EYE --look-at TARGET --fov FOVX (core/camera.h
// Pose::LookAt: no roll, image up towards the zenith).
function viewProj(width, height) {
  const e = gl3(eyeEnu()), t = gl3(cam.target);
  const f = norm(sub(t, e));
  let r = cross(f, [0, 1, 0]);
  if (Math.hypot(r[0], r[1], r[2]) < 1e-9) r = cross(f, [0, 0, -1]);
  r = norm(r);
  const u = cross(r, f);
  const tx = Math.tan(cam.fovX * Math.PI / 360), ty = tx * height / width;
  const ext = Math.max(D.bbox.max[0] - D.bbox.min[0], D.bbox.max[1] - D.bbox.min[1], D.bbox.max[2] - D.bbox.min[2]);
  const near = Math.max(0.01, cam.distance * 0.01), far = cam.distance + 4 * ext + 10;
  const view = [r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
                -dot(r, e), -dot(u, e), dot(f, e), 1];
  const proj = [1 / tx, 0, 0, 0, 0, 1 / ty, 0, 0, 0, 0, -(far + near) / (far - near), -1,
                0, 0, -2 * far * near / (far - near), 0];
  const m = new Array(16).fill(0);
  for (let c = 0; c < 4; ++c)
    for (let row = 0; row < 4; ++row)
      for (let k = 0; k < 4; ++k) m[c * 4 + row] += proj[k * 4 + row] * view[c * 4 + k];
  return { matrix: m, eye: e };
}

// ---- state and drawing ----------------------------------------------------------------------
const N = D.bases.length;
const state = { f: 0.5, pbs: 0, ev: 0, auto: false, response: !!D.response };
// One exposure for the whole day (noon's), or each time's own (log-interpolated between the
// bases, and between clear and overcast), times the slider's stops.
function exposure() {
  let e = D.exposure;
  if (state.auto) {
    const b = bracket(state.f), B0 = D.bases[b.i0], B1 = D.bases[b.i1];
    const lerp = (p, q, w) => Math.exp(Math.log(p) + w * (Math.log(q) - Math.log(p)));
    e = lerp(lerp(B0.exposure, B1.exposure, b.w), lerp(B0.exposure_overcast, B1.exposure_overcast, b.w),
             state.pbs);
  }
  return e * Math.pow(2, state.ev) * (state.response ? D.response.exposure_scale : 1);
}
const timeInput = document.getElementById("time");
const overcastInput = document.getElementById("overcast");
const exposureInput = document.getElementById("exposure");
function timeAt(f) { return D.sunrise + f * (D.sunset - D.sunrise); }
function hhmm(seconds) {
  const d = new Date(Math.round(seconds) * 1000);
  return String(d.getUTCHours()).padStart(2, "0") + ":" + String(d.getUTCMinutes()).padStart(2, "0");
}
// The bases around fraction f of the day (the bases are evenly spaced from sunrise to sunset).
function bracket(f) {
  const x = Math.max(0, Math.min(1, f)) * (N - 1);
  const i0 = Math.min(N - 2, Math.floor(x));
  return { i0: i0, i1: i0 + 1, w: x - i0 };
}
function draw() {
  const w = Math.max(1, Math.round(canvas.clientWidth * devicePixelRatio));
  const h = Math.max(1, Math.round(canvas.clientHeight * devicePixelRatio));
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  gl.viewport(0, 0, w, h);
  gl.clearColor(0.125, 0.141, 0.165, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!viewer.ready) return;
  const b = bracket(state.f), B0 = D.bases[b.i0], B1 = D.bases[b.i1];
  const vp = viewProj(w, h);
  gl.useProgram(prog);
  gl.uniformMatrix4fv(U.uViewProj, false, vp.matrix);
  gl.uniform3fv(U.uEye, vp.eye);
  gl.uniform1f(U.uLayer0, b.i0);
  gl.uniform1f(U.uLayer1, b.i1);
  gl.uniform1f(U.uW, b.w);
  gl.uniform1f(U.uPbs, state.pbs);
  gl.uniform1f(U.uExposure, exposure());
  gl.uniform1f(U.uGamma, D.gamma);
  gl.uniform2f(U.uAlbScale, D.albedo.sun.scale, D.albedo.se.scale);
  gl.uniform2f(U.uSeScale, B0.se_scale, B1.se_scale);
  gl.uniform2f(U.uSeoScale, B0.se_overcast_scale, B1.se_overcast_scale);
  gl.uniform3fv(U.uSunDir0, B0.sun_dir);
  gl.uniform3fv(U.uSunDir1, B1.sun_dir);
  gl.uniform3fv(U.uSunE0, B0.sun_e);
  gl.uniform3fv(U.uSunE1, B1.sun_e);
  gl.uniform1i(U.uAlbedo, 0);
  gl.uniform1i(U.uVis, 1);
  gl.uniform1i(U.uSe, 2);
  gl.uniform1i(U.uSeo, 3);
  gl.uniform1i(U.uLut, 4);
  gl.uniform1i(U.uResponse, state.response ? 1 : 0);
  gl.uniform1f(U.uLogLo, D.response ? D.response.log_lo : 0);
  gl.uniform1f(U.uLogHi, D.response ? D.response.log_hi : 1);
  gl.enable(gl.DEPTH_TEST);
  gl.bindVertexArray(vao);
  gl.drawArrays(gl.TRIANGLES, 0, vertexCount);
  viewer.frames += 1;
  const t = timeAt(state.f);
  const el = B0.sun_elevation_deg + b.w * (B1.sun_elevation_deg - B0.sun_elevation_deg);
  const solar = t + D.site.lon_deg * 240;
  document.getElementById("time-value").textContent = hhmm(t) + "  (solar " + hhmm(solar) + ")";
  document.getElementById("overcast-value").textContent = Math.round(state.pbs * 100) + " %";
  document.getElementById("exposure-value").textContent = (state.ev >= 0 ? "+" : "") + state.ev.toFixed(1);
  document.getElementById("sun").textContent = "Sun elevation " + el.toFixed(1) + " deg; " +
      new Date(t * 1000).toISOString().slice(0, 10) + ", sunrise " + hhmm(D.sunrise) +
      ", sunset " + hhmm(D.sunset) + " UTC";
}
let pending = false;
function redraw() {
  if (pending) return;
  pending = true;
  requestAnimationFrame(() => { pending = false; draw(); });
}
timeInput.addEventListener("input", () => { state.f = timeInput.value / 1000; redraw(); });
overcastInput.addEventListener("input", () => { state.pbs = overcastInput.value / 100; redraw(); });
exposureInput.addEventListener("input", () => { state.ev = Number(exposureInput.value); redraw(); });
const responseInput = document.getElementById("response");
if (!D.response) document.getElementById("response-label").style.display = "none";
responseInput.checked = state.response;
responseInput.addEventListener("change", () => { state.response = responseInput.checked && !!D.response; redraw(); });
const autoInput = document.getElementById("auto");
autoInput.addEventListener("change", () => { state.auto = autoInput.checked; redraw(); });
window.addEventListener("resize", redraw);

// Mouse and touch: drag orbits, shift-drag pans, the wheel zooms.
let drag = null;
canvas.addEventListener("pointerdown", (e) => {
  drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
  canvas.setPointerCapture(e.pointerId);
});
canvas.addEventListener("pointerup", () => { drag = null; });
canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag.x = e.clientX; drag.y = e.clientY;
  if (drag.pan) {
    const s = cam.distance * Math.tan(cam.fovX * Math.PI / 360) * 2 / canvas.clientWidth;
    const right = [-Math.cos(cam.azimuth), Math.sin(cam.azimuth), 0];
    cam.target = [cam.target[0] - right[0] * dx * s, cam.target[1] - right[1] * dx * s,
                  cam.target[2] + dy * s];
  } else {
    cam.azimuth -= dx * 0.006;
    cam.elevation = Math.max(-1.5, Math.min(1.5, cam.elevation + dy * 0.006));
  }
  redraw();
});
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  cam.distance = Math.max(0.5, cam.distance * Math.exp(e.deltaY * 0.001));
  redraw();
}, { passive: false });

// ---- the interface tests and scripts use -------------------------------------------------------
viewer.data = { times: D.bases.map((b) => b.utc), exposure: D.exposure, sunrise: D.sunrise,
                sunset: D.sunset };
viewer.setFraction = (f) => { state.f = Math.max(0, Math.min(1, f)); timeInput.value = Math.round(state.f * 1000); draw(); };
viewer.setBase = (i) => viewer.setFraction(i / (N - 1));
viewer.setTime = (unixSeconds) => viewer.setFraction((unixSeconds - D.sunrise) / (D.sunset - D.sunrise));
viewer.setOvercast = (p) => { state.pbs = Math.max(0, Math.min(1, p)); overcastInput.value = Math.round(state.pbs * 100); draw(); };
viewer.setExposureEv = (ev) => { state.ev = ev; exposureInput.value = ev; draw(); };
viewer.setControlsVisible = (on) => { document.getElementById("panel").style.display = on ? "" : "none"; };
viewer.setCamera = (c) => { setCameraEnu(c.eye, c.target, c.fov_x_deg); draw(); };
viewer.camera = () => ({ eye: eyeEnu(), target: cam.target.slice(), fov_x_deg: cam.fovX,
                         width: canvas.width, height: canvas.height });
viewer.state = () => { const b = bracket(state.f); return { time: new Date(timeAt(state.f) * 1000).toISOString(),
                       i0: b.i0, i1: b.i1, w: b.w, pbs: state.pbs,
                       exposure: exposure(), auto_exposure: state.auto,
                       tone: state.response ? "response" : "srgb" }; };
viewer.setResponse = (on) => { state.response = !!on && !!D.response; responseInput.checked = state.response; draw(); };
viewer.setAutoExposure = (on) => { state.auto = !!on; autoInput.checked = state.auto; draw(); };
viewer.draw = draw;

setCameraEnu(D.camera.eye, D.camera.target, D.camera.fov_x_deg);
// Noon first, unless the address says otherwise: index.html#t=0.25&overcast=0.5&ev=1 (t the
// fraction of the day from sunrise to sunset, overcast the blocked fraction 0..1, ev in stops).
state.f = Math.max(0, Math.min(1, (D.noon - D.sunrise) / (D.sunset - D.sunrise)));
const hash = new URLSearchParams(location.hash.slice(1));
const number = (key, lo, hi) => {
  const v = Number(hash.get(key));
  return hash.has(key) && Number.isFinite(v) ? Math.max(lo, Math.min(hi, v)) : null;
};
if (number("t", 0, 1) !== null) state.f = number("t", 0, 1);
if (number("overcast", 0, 1) !== null) state.pbs = number("overcast", 0, 1);
if (number("ev", -6, 6) !== null) state.ev = number("ev", -6, 6);
if (hash.get("controls") === "0") viewer.setControlsVisible(false);
if (hash.get("auto") === "1") { state.auto = true; autoInput.checked = true; }
if (hash.get("response") === "0") { state.response = false; responseInput.checked = false; }
timeInput.value = Math.round(state.f * 1000);
overcastInput.value = Math.round(state.pbs * 100);
exposureInput.value = state.ev;
draw();
message.textContent = "loading textures...";
Promise.all([
  textureArray(0, [D.albedo.sun.png, D.albedo.se.png], D.atlas, false),
  textureArray(1, D.bases.map((b) => b.vis), D.shadow_atlas, true),
  textureArray(2, D.bases.map((b) => b.se), D.atlas, false),
  textureArray(3, D.bases.map((b) => b.se_overcast), D.atlas, false),
  D.response ? loadImage(D.response.lut).then((img) => {
    const tex = gl.createTexture();
    gl.activeTexture(gl.TEXTURE4);
    gl.bindTexture(gl.TEXTURE_2D, tex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, img);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
  }) : Promise.resolve().then(() => {
    // No response: a 1x1 table, so that the sampler is never unbound.
    gl.activeTexture(gl.TEXTURE4);
    gl.bindTexture(gl.TEXTURE_2D, gl.createTexture());
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, 1, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
  }),
]).then(() => {
  message.textContent = "";
  viewer.ready = true;
  draw();
  const err = gl.getError();
  if (err !== gl.NO_ERROR) console.error("WebGL error " + err);
  readyResolve(viewer.renderer);
}).catch((e) => {
  message.textContent = String(e);
  console.error(String(e));
  readyReject(e);
});
})();
</script>
</body>
</html>
)ROUENPAGE";
}

}  // namespace rouen
