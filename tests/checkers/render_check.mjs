#!/usr/bin/env node
// Render a .glb written by blendsim in a real browser: three.js in headless Chromium.
//
// usage: node render_check.mjs FILE.glb OUT_DIR [--times=A,B]
//
// Serves a small page on 127.0.0.1 (ephemeral port) that loads three.js's ES modules from
// node_modules through an import map, loads FILE with GLTFLoader, frames the camera on the
// mesh's bounds over both times, and renders at animation times A and B (default: the start
// and the middle of the animation). playwright-core drives /usr/bin/chromium (software GL)
// with a fresh user-data-dir, screenshots the canvas at each time, and the page checks with
// readPixels that the mesh covers a reasonable fraction of the image (it is visible) and that
// the two renders differ (it moves).
//
// Writes OUT_DIR/render-0.png, OUT_DIR/render-1.png and OUT_DIR/render.json (the summary,
// also printed as one line on stdout). Exit code 0 when everything passes, 1 otherwise.

import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { inChromium, pageStart, runChecker, serve } from './browser.mjs';

const SIZE = { width: 480, height: 360 };
// Visible: the mesh covers between these fractions of the image. Moves: at least this
// fraction of the pixels changes between the two times.
const COVERAGE = [0.02, 0.9];
const CHANGED = 0.005;
// Only turns a hang into a failure: far above the few seconds a render takes, so that a
// loaded machine (CI's 2 cores at load 20, software rendering) never reaches it.
const TIMEOUT_MS = 900_000;

const PAGE = `${pageStart('blendsim render check', SIZE)}
scene.background = new THREE.Color(0x202838);
scene.add(new THREE.AmbientLight(0xffffff, 0.5));
const sun = new THREE.DirectionalLight(0xffffff, 2.5);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(35, W / H, 0.01, 100);

let mesh, mixer, actions, background, previous;

function setTime(t) {
  actions.forEach((a) => a.reset());
  mixer.setTime(t);
  scene.updateMatrixWorld(true);
}

// World-space positions of the morphed mesh (three morphs on the GPU; the bounds need the CPU).
function worldPoints() {
  const g = mesh.geometry, base = g.attributes.position, morphs = g.morphAttributes.position ?? [];
  const w = mesh.morphTargetInfluences ?? [], out = [];
  for (let v = 0; v < base.count; v++) {
    const p = new THREE.Vector3(base.getX(v), base.getY(v), base.getZ(v));
    morphs.forEach((m, j) => { if (w[j]) p.add(new THREE.Vector3(m.getX(v), m.getY(v), m.getZ(v)).multiplyScalar(w[j])); });
    out.push(p.applyMatrix4(mesh.matrixWorld));
  }
  return out;
}

function pixels() {
  renderer.render(scene, camera);
  const buf = new Uint8Array(W * H * 4);
  gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, buf);
  return buf;
}

function fractionDiffering(a, b) {
  let n = 0;
  for (let i = 0; i < a.length; i += 4) {
    if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 24) n++;
  }
  return n / (a.length / 4);
}

window.prepare = async (times) => {
  const gltf = await new GLTFLoader().loadAsync('/model.glb');
  scene.add(gltf.scene);
  gltf.scene.traverse((o) => { if (o.isMesh) mesh = o; });
  if (!mesh) throw new Error('no mesh in the file');
  mixer = new THREE.AnimationMixer(gltf.scene);
  actions = gltf.animations.map((clip) => {
    const a = mixer.clipAction(clip);
    a.setLoop(THREE.LoopOnce);
    a.clampWhenFinished = true;
    return a.play();
  });
  const duration = Math.max(0, ...gltf.animations.map((c) => c.duration));
  times = times ?? [0, duration / 2];
  const box = new THREE.Box3();
  for (const t of times) {
    setTime(t);
    for (const p of worldPoints()) box.expandByPoint(p);
  }
  const sphere = box.getBoundingSphere(new THREE.Sphere());
  const distance = 1.15 * sphere.radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2));
  camera.position.copy(sphere.center).add(new THREE.Vector3(1, 0.6, 1.4).normalize().multiplyScalar(distance));
  camera.near = distance / 100; camera.far = distance * 10;
  camera.lookAt(sphere.center);
  camera.updateProjectionMatrix();
  sun.position.copy(camera.position).add(new THREE.Vector3(0, sphere.radius, 0));
  sun.target.position.copy(sphere.center);
  sun.target.updateMatrixWorld();
  mesh.visible = false;
  background = pixels();
  mesh.visible = true;
  const debug = gl.getExtension('WEBGL_debug_renderer_info');
  return { times, duration, gl: debug ? gl.getParameter(debug.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER) };
};

window.renderAt = (t) => {
  setTime(t);
  const now = pixels();
  const result = { time: t, coverage: fractionDiffering(now, background), changed: previous ? fractionDiffering(now, previous) : null };
  previous = now;
  return result;
};
window.pageReady = true;
</script></body></html>`;

async function main() {
  const positional = process.argv.slice(2).filter((a) => !a.startsWith('--'));
  const timesArg = process.argv.find((a) => a.startsWith('--times='));
  if (positional.length !== 2) {
    console.error('usage: node render_check.mjs FILE.glb OUT_DIR [--times=A,B]');
    return 2;
  }
  const [file, outDir] = positional.map((p) => resolve(p));
  const times = timesArg ? timesArg.slice('--times='.length).split(',').map(Number) : null;
  mkdirSync(outDir, { recursive: true });
  const summary = { file, issues: [], screenshots: [] };
  const server = await serve(PAGE, (path) => (path === '/model.glb' ? [readFileSync(file), 'model/gltf-binary'] : null));
  await inChromium(server, SIZE, summary.issues, async (page) => {
    Object.assign(summary, await page.evaluate((t) => window.prepare(t), times));
    summary.renders = [];
    for (const [i, t] of summary.times.entries()) {
      const r = await page.evaluate((t) => window.renderAt(t), t);
      const png = join(outDir, `render-${i}.png`);
      await page.locator('canvas').screenshot({ path: png });
      summary.renders.push(r);
      summary.screenshots.push(png);
      if (r.coverage < COVERAGE[0] || r.coverage > COVERAGE[1]) {
        summary.issues.push(`at ${t} s the mesh covers ${(100 * r.coverage).toFixed(1)}% of the image, expected ${100 * COVERAGE[0]}-${100 * COVERAGE[1]}%`);
      }
    }
    const changed = summary.renders.at(-1).changed;
    summary.changed = changed;
    if (!(changed >= CHANGED)) summary.issues.push(`only ${(100 * changed).toFixed(2)}% of the pixels change between ${summary.times.join(' s and ')} s: the animation does not move`);
  });
  summary.ok = summary.issues.length === 0;
  for (const issue of summary.issues) console.error(`${file}: ${issue}`);
  writeFileSync(join(outDir, 'render.json'), JSON.stringify(summary, null, 2) + '\n');
  console.log(JSON.stringify(summary));
  return summary.ok ? 0 : 1;
}

runChecker('render_check.mjs', main, TIMEOUT_MS);
