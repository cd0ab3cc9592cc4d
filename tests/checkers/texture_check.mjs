#!/usr/bin/env node
// Check that a textured .glb written by blendsim maps its texture right, by rendering it and
// an independent reference in a real browser: three.js in headless Chromium.
//
// usage: node texture_check.mjs FILE.glb[,FILE2.glb...] TEXTURE.png OUT_DIR TIME=KEY.obj [TIME=KEY.obj ...] [--view=X,Y,Z]
//
// --view: the direction from the meshes' centre to the camera (default 1,0.7,1.3).
//
// For each FILE, at each TIME (seconds), renders the glb's animation at that time with
// GLTFLoader (its own embedded texture, baseColorTexture, which must exist) and, from the
// same camera, the keyframe OBJ that the animation passes through at that time, loaded with
// three's OBJLoader and textured with TEXTURE by TextureLoader (the OBJ's own `vt`, v up).
// Both are drawn unlit (MeshBasicMaterial with the map, both sides), so the only thing that
// can differ is where the texture lands. `mismatch` is the fraction of the pixels covered by
// either mesh whose colours differ by more than DIFF (sum over RGB, of 765); the file passes
// when every time's mismatch is below MAX_MISMATCH and the glb covers what the OBJ covers.
//
// Writes OUT_DIR/texture-F-K-glb.png and -obj.png (F file, K time), OUT_DIR/texture.json
// (summary, also printed as one line on stdout). Exit code 0 when every file passes, 1 otherwise.

import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { inChromium, pageStart, runChecker, serve } from './browser.mjs';

const SIZE = { width: 400, height: 400 };
const DIFF = 48;
const MAX_MISMATCH = 0.02;
// Only turns a hang into a failure (see render_check.mjs).
const TIMEOUT_MS = 1_200_000;

const PAGE = `${pageStart('blendsim texture check', SIZE, ['OBJLoader'])}
scene.background = new THREE.Color(0x000000);
const camera = new THREE.PerspectiveCamera(35, W / H, 0.01, 100);
let texture, objs = {}, framed = false;

function pixels() {
  renderer.render(scene, camera);
  const buf = new Uint8Array(W * H * 4);
  gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, buf);
  return buf;
}

const unlit = (map) => new THREE.MeshBasicMaterial({ map, side: THREE.DoubleSide });

window.prepare = async (poses, view) => {
  texture = await new THREE.TextureLoader().loadAsync('/texture');
  texture.colorSpace = THREE.SRGBColorSpace;
  texture.wrapS = texture.wrapT = THREE.RepeatWrapping;
  const box = new THREE.Box3();
  for (const [i, p] of poses.entries()) {
    const group = new OBJLoader().parse(await (await fetch('/obj/' + i)).text());
    group.traverse((o) => { if (o.isMesh) o.material = Array.isArray(o.material) ? o.material.map(() => unlit(texture)) : unlit(texture); });
    group.visible = false;
    scene.add(group);
    box.expandByObject(group);
    objs[p.time] = group;
  }
  // One camera for everything: the keys' bounds, seen from above the side.
  const sphere = box.getBoundingSphere(new THREE.Sphere());
  const distance = 1.1 * sphere.radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2));
  camera.position.copy(sphere.center).add(new THREE.Vector3(...view).normalize().multiplyScalar(distance));
  camera.near = distance / 100; camera.far = distance * 10;
  camera.lookAt(sphere.center);
  camera.updateProjectionMatrix();
  return { renderer: gl.getParameter(gl.RENDERER) };
};

window.compare = async (file, times) => {
  const gltf = await new GLTFLoader().loadAsync('/glb/' + file);
  const issues = [];
  let maps = 0;
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    if (o.material.map) maps++;
    o.material = unlit(o.material.map ?? null);
  });
  if (maps === 0) issues.push('no primitive has a baseColorTexture');
  scene.add(gltf.scene);
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const actions = gltf.animations.map((c) => { const a = mixer.clipAction(c); a.setLoop(THREE.LoopOnce); a.clampWhenFinished = true; return a.play(); });
  const results = [];
  for (const t of times) {
    actions.forEach((a) => a.reset());
    mixer.setTime(t);
    scene.updateMatrixWorld(true);
    gltf.scene.visible = true; objs[t].visible = false;
    const a = pixels();
    const glbPng = renderer.domElement.toDataURL('image/png');
    gltf.scene.visible = false; objs[t].visible = true;
    const b = pixels();
    const objPng = renderer.domElement.toDataURL('image/png');
    objs[t].visible = false;
    let covered = 0, differ = 0, coveredGlb = 0, coveredObj = 0;
    for (let i = 0; i < a.length; i += 4) {
      const inA = a[i] + a[i + 1] + a[i + 2] > 0, inB = b[i] + b[i + 1] + b[i + 2] > 0;
      coveredGlb += inA; coveredObj += inB;
      if (!inA && !inB) continue;
      covered++;
      if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > ${DIFF}) differ++;
    }
    const mismatch = differ / Math.max(covered, 1);
    results.push({ time: t, covered: covered / (W * H), coverage_glb: coveredGlb / (W * H), coverage_obj: coveredObj / (W * H), mismatch, glbPng, objPng });
    if (!(mismatch < ${MAX_MISMATCH})) issues.push(\`at \${t} s \${(100 * mismatch).toFixed(2)}% of the covered pixels differ from the OBJ keyframe rendered with the same texture (at most ${100 * MAX_MISMATCH}%)\`);
    if (coveredObj < 0.02 * W * H) issues.push(\`at \${t} s the OBJ keyframe covers only \${coveredObj} pixels\`);
  }
  scene.remove(gltf.scene);
  return { file, maps, results, issues };
};
window.pageReady = true;
</script></body></html>`;

async function main() {
  const view = (process.argv.find((a) => a.startsWith('--view='))?.slice(7) ?? '1,0.7,1.3').split(',').map(Number);
  const args = process.argv.slice(2).filter((a) => !a.startsWith('--'));
  if (args.length < 4) {
    console.error('usage: node texture_check.mjs FILE.glb[,FILE2.glb...] TEXTURE.png OUT_DIR TIME=KEY.obj [TIME=KEY.obj ...]');
    return 2;
  }
  const files = args[0].split(',').map((f) => resolve(f));
  const [texture, outDir] = [resolve(args[1]), resolve(args[2])];
  const poses = args.slice(3).map((a) => { const i = a.indexOf('='); return { time: Number(a.slice(0, i)), obj: resolve(a.slice(i + 1)) }; });
  mkdirSync(outDir, { recursive: true });
  const summary = { texture, poses, view, issues: [], files: [] };
  const [glbs, png, objs] = [files.map((f) => readFileSync(f)), readFileSync(texture), poses.map((p) => readFileSync(p.obj, 'utf8'))];
  const server = await serve(PAGE, (path) => {
    if (path === '/texture') return [png, 'image/png'];
    if (path.startsWith('/obj/')) return [objs[Number(path.slice(5))] ?? null, 'text/plain'];
    if (path.startsWith('/glb/')) return [glbs[Number(path.slice(5))] ?? null, 'model/gltf-binary'];
    return null;
  });
  await inChromium(server, SIZE, summary.issues, async (page) => {
    Object.assign(summary, await page.evaluate((p) => window.prepare(...p), [poses.map((p) => ({ time: p.time })), view]));
    for (const [f, file] of files.entries()) {
      const r = await page.evaluate(([i, t]) => window.compare(i, t), [f, poses.map((p) => p.time)]);
      r.file = file;
      for (const [k, x] of r.results.entries()) {
        for (const which of ['glb', 'obj']) {
          const png = join(outDir, `texture-${f}-${k}-${which}.png`);
          writeFileSync(png, Buffer.from(x[`${which}Png`].split(',')[1], 'base64'));
          delete x[`${which}Png`];
          x[which] = png;
        }
      }
      r.ok = r.issues.length === 0;
      for (const issue of r.issues) console.error(`${file}: ${issue}`);
      summary.files.push(r);
    }
  });
  for (const issue of summary.issues) console.error(`${texture}: ${issue}`);
  summary.ok = summary.issues.length === 0 && summary.files.every((f) => f.ok);
  writeFileSync(join(outDir, 'texture.json'), JSON.stringify(summary, null, 2) + '\n');
  console.log(JSON.stringify(summary));
  return summary.ok ? 0 : 1;
}

runChecker('texture_check.mjs', main, TIMEOUT_MS, { files: [] });
